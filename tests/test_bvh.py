"""BVH parsing, forward kinematics, rig name maps, units and up-axis detection."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from posedrift.skeleton import JOINT_INDEX, joint_angles, t_pose_joints
from posedrift.synthetic import bvh_motion, load_bvh, parse_bvh
from posedrift.synthetic._bvh import EXAMPLE_BVH
from posedrift.synthetic._rigs import detect_units, resolve_rig

H = 1.75

# --------------------------------------------------------------------------- parsing, FK


def test_example_fk_by_hand():
    bvh = parse_bvh(EXAMPLE_BVH)
    assert bvh.names == ("Hips", "Spine", "Head", "Head/End Site")
    assert bvh.parents == (-1, 0, 1, 2)
    assert bvh.n_frames == 2 and bvh.fps == 25.0
    pos = bvh.positions()
    np.testing.assert_allclose(pos[0], [[0, 0, 0], [0, 10, 0], [0, 15, 0], [0, 18, 0]], atol=1e-12)
    # Frame 1: root at x = 1 turned 90 degrees about Z: +Y goes to -X.
    np.testing.assert_allclose(
        pos[1], [[1, 0, 0], [-9, 0, 0], [-14, 0, 0], [-17, 0, 0]], atol=1e-12
    )
    # A subset gives the same numbers.
    np.testing.assert_allclose(bvh.positions(["Head/End Site", "Spine"]), pos[:, [3, 1]])


@pytest.mark.parametrize("order", ["ZXY", "XYZ", "YZX", "ZYX"])
def test_channel_order_matches_scipy_intrinsic_euler(order):
    angles = np.array([[30.0, -50.0, 70.0], [-120.0, 10.0, 5.0]])
    chans = " ".join(f"{a}rotation" for a in order)
    text = f"""HIERARCHY
ROOT A
{{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition {chans}
  JOINT B
  {{
    OFFSET 0 0 0
    CHANNELS 3 {chans}
    End Site
    {{
      OFFSET 1 2 3
    }}
  }}
}}
MOTION
Frames: 2
Frame Time: 0.01
"""
    rows = [f"0.5 -1 2 {' '.join(map(str, a))} {' '.join(map(str, a[::-1]))}" for a in angles]
    bvh = parse_bvh(text + "\n".join(rows) + "\n")
    got = bvh.positions(["B/End Site"])[:, 0]
    for k, a in enumerate(angles):
        r = Rotation.from_euler(order, a, degrees=True) * Rotation.from_euler(
            order, a[::-1], degrees=True
        )
        np.testing.assert_allclose(got[k], np.array([0.5, -1, 2]) + r.apply([1, 2, 3]), atol=1e-9)


def test_mixed_channel_orders_per_joint_and_end_sites(tmp_path):
    path = tmp_path / "mix.bvh"
    path.write_text(_rig_bvh(CGSPEED_NAMES, order_override="ZXY"))
    bvh = load_bvh(path)
    assert "LeftHand/End Site" in bvh.names
    assert bvh.channels[bvh.index("LeftForeArm")] == ("Zrotation", "Xrotation", "Yrotation")


# --------------------------------------------------------------------------- bad input


def _example_lines() -> list[str]:
    return EXAMPLE_BVH.splitlines()


def test_truncated_data_names_file_and_line():
    lines = _example_lines()
    lines[-1] = "1 0 0 90 0"  # the last frame cut short
    with pytest.raises(ValueError, match=r"bad\.bvh, line 25 \(frame 1\).*5 values, expected 12"):
        parse_bvh("\n".join(lines), source="bad.bvh")


def test_truncated_hierarchy():
    text = EXAMPLE_BVH[: EXAMPLE_BVH.index("JOINT Head")]
    with pytest.raises(ValueError, match=r"cut\.bvh, line \d+: the hierarchy ends early"):
        parse_bvh(text, source="cut.bvh")


def test_frame_count_mismatch():
    text = EXAMPLE_BVH.replace("Frames: 2", "Frames: 3")
    with pytest.raises(ValueError, match=r"n\.bvh: 'Frames: 3' \(line 22\) but the file holds 2"):
        parse_bvh(text, source="n.bvh")


def test_nan_channel_names_frame_and_line():
    lines = _example_lines()
    lines[-1] = "1 0 0 90 0 0 0 nan 0 0 0 0"
    with pytest.raises(
        ValueError, match=r"x\.bvh, line 25 \(frame 1\): channel 7 \(Spine Xrotation\) is nan"
    ):
        parse_bvh("\n".join(lines), source="x.bvh")


def test_not_a_number():
    lines = _example_lines()
    lines[-2] = "0 0 0 0 0 zero 0 0 0 0 0 0"
    with pytest.raises(ValueError, match=r"line 24 \(frame 0\): 'zero' is not a number"):
        parse_bvh("\n".join(lines), source="x.bvh")


@pytest.mark.parametrize(
    ("old", "new", "message"),
    [
        ("HIERARCHY", "HIERARCH", "must start with 'HIERARCHY'"),
        (
            "CHANNELS 3 Zrotation Xrotation Yrotation\n      End",
            "CHANNELS 3 Zrot Xrotation Yrotation\n      End",
            "unknown channel 'Zrot'",
        ),
        ("OFFSET 0 5 0", "OFFSET 0 five 0", "expected a number for the OFFSET of 'Head'"),
        ("Frame Time: 0.04", "Frame Time: 0", "'Frame Time:' must be a positive"),
        ("JOINT Head", "JOINT Spine", "the joint name 'Spine' appears twice"),
    ],
)
def test_malformed_hierarchy(old, new, message):
    assert old in EXAMPLE_BVH
    with pytest.raises(ValueError, match=r"m\.bvh.*" + message.replace("(", r"\(")):
        parse_bvh(EXAMPLE_BVH.replace(old, new, 1), source="m.bvh")


def test_missing_motion_section():
    text = EXAMPLE_BVH[: EXAMPLE_BVH.index("MOTION")]
    with pytest.raises(ValueError, match=r"m\.bvh: no 'MOTION' section"):
        parse_bvh(text, source="m.bvh")


def test_missing_file(tmp_path):
    with pytest.raises(ValueError, match="Cannot read BVH file .*nope.bvh"):
        load_bvh(tmp_path / "nope.bvh")


def test_utf8_byte_order_mark_is_ignored(tmp_path):
    plain = parse_bvh(EXAMPLE_BVH)
    path = tmp_path / "bom.bvh"
    path.write_bytes(b"\xef\xbb\xbf" + EXAMPLE_BVH.replace("\n", "\r\n").encode())
    for bvh in (load_bvh(path), parse_bvh("\ufeff" + EXAMPLE_BVH)):
        assert bvh.names == plain.names and bvh.n_frames == plain.n_frames
        np.testing.assert_array_equal(bvh.positions(), plain.positions())
    # a BOM anywhere else is still an error at line 1
    with pytest.raises(ValueError, match="line 1: a BVH file must start with 'HIERARCHY'"):
        parse_bvh(" \ufeff" + EXAMPLE_BVH)


# --------------------------------------------------------------------------- constructed rigs

# Template skeleton (metres, +Y up, facing +Z, person's left +X): the roles a rig names.
_R = {
    "ankle_y": 0.039 * H,
    "hip_y": 0.530 * H,
    "sh_y": 0.818 * H,
    "hh": 0.5 * 0.191 * H,
    "hs": 0.5 * 0.259 * H,
}


def _template() -> dict[str, tuple[str | None, np.ndarray]]:
    """role -> (parent role, position): a T-pose whose 15 joints are t_pose_joints(H)."""
    tp = t_pose_joints(H)
    j = {n: tp[i] for n, i in JOINT_INDEX.items()}
    hip_y = _R["hip_y"]
    out: dict[str, tuple[str | None, np.ndarray]] = {
        "root": (None, np.array([0.0, hip_y, 0.0])),
        "spine": ("root", np.array([0.0, hip_y + 0.1 * H, 0.0])),
        "chest": ("spine", np.array([0.0, _R["sh_y"] - 0.06 * H, 0.0])),
        "neck_low": ("chest", np.array([0.0, _R["sh_y"] - 0.04 * H, 0.0])),
        "neck": ("neck_low", j["neck"]),
        "head": ("neck", np.array([0.0, 0.87 * H, 0.0])),
        "head_top": ("head", np.array([0.0, H, 0.0])),
    }
    for side, s in (("l", 1.0), ("r", -1.0)):
        p = f"{side}_"
        name = "left" if side == "l" else "right"
        out[p + "clav"] = ("chest", np.array([s * 0.03 * H, _R["sh_y"] - 0.02 * H, 0.0]))
        out[p + "shoulder"] = (p + "clav", j[f"{name}_shoulder"])
        out[p + "elbow"] = (p + "shoulder", j[f"{name}_elbow"])
        out[p + "wrist"] = (p + "elbow", j[f"{name}_hand"])
        out[p + "mid2"] = (p + "wrist", j[f"{name}_hand"] + [s * 0.07 * H, 0, 0])
        out[p + "mid3"] = (p + "mid2", j[f"{name}_hand"] + [s * 0.09 * H, 0, 0])
        out[p + "tip"] = (p + "mid3", j[f"{name}_hand"] + [s * 0.11 * H, 0, 0])
        out[p + "hip"] = ("root", j[f"{name}_hip"])
        out[p + "knee"] = (p + "hip", j[f"{name}_knee"])
        out[p + "ankle"] = (p + "knee", j[f"{name}_foot"])
        out[p + "ball"] = (p + "ankle", np.array([s * _R["hh"], 0.02 * H, 0.08 * H]))
        out[p + "toe1"] = (p + "ball", np.array([s * _R["hh"], 0.01 * H, 0.10 * H]))
        out[p + "toe"] = (p + "toe1", np.array([s * _R["hh"], 0.0, 0.12 * H]))
    return out


# Rig naming: role -> node name; None drops the role (its children hang from its parent);
# "END" makes the role an End Site.
CGSPEED_NAMES = {
    "root": "Hips", "spine": "Spine", "chest": "Spine1", "neck_low": "Neck", "neck": "Neck1",
    "head": "Head", "head_top": "END",
    "l_clav": "LeftShoulder", "l_shoulder": "LeftArm", "l_elbow": "LeftForeArm",
    "l_wrist": "LeftHand", "l_mid2": None, "l_mid3": None, "l_tip": "END",
    "l_hip": "LeftUpLeg", "l_knee": "LeftLeg", "l_ankle": "LeftFoot", "l_ball": None,
    "l_toe1": "LeftToeBase", "l_toe": "END",
}  # fmt: skip
CMU_ORIGINAL_NAMES = {
    "root": "Hips", "spine": "lowerback", "chest": "Chest2", "neck_low": "lowerneck",
    "neck": "Neck", "head": "Head", "head_top": "END",
    "l_clav": "LeftCollar", "l_shoulder": "LeftShoulder", "l_elbow": "LeftElbow",
    "l_wrist": "LeftWrist", "l_mid2": None, "l_mid3": "LFingers", "l_tip": "END",
    "l_hip": "LeftHip", "l_knee": "LeftKnee", "l_ankle": "LeftAnkle", "l_ball": None,
    "l_toe1": "LeftToe", "l_toe": "END",
}  # fmt: skip
CC_BASE_NAMES = {
    "root": "CC_Base_Hip", "spine": "CC_Base_Waist", "chest": "CC_Base_Spine02",
    "neck_low": None, "neck": "CC_Base_NeckTwist01", "head": "CC_Base_Head",
    "head_top": None,
    "l_clav": "CC_Base_L_Clavicle", "l_shoulder": "CC_Base_L_Upperarm",
    "l_elbow": "CC_Base_L_Forearm", "l_wrist": "CC_Base_L_Hand", "l_mid2": "CC_Base_L_Mid2",
    "l_mid3": "CC_Base_L_Mid3", "l_tip": None,
    "l_hip": "CC_Base_L_Thigh", "l_knee": "CC_Base_L_Calf", "l_ankle": "CC_Base_L_Foot",
    "l_ball": "CC_Base_L_ToeBase", "l_toe1": "CC_Base_L_MidToe1", "l_toe": None,
}  # fmt: skip
GAME_NAMES = {
    "root": "Hips", "spine": "Spine", "chest": "Chest", "neck_low": None, "neck": "Neck",
    "head": "Head", "head_top": "END",
    "l_clav": "Shoulder_L", "l_shoulder": "UpperArm_L", "l_elbow": "LowerArm_L",
    "l_wrist": "Hand_L", "l_mid2": None, "l_mid3": None, "l_tip": "END",
    "l_hip": "UpperLeg_L", "l_knee": "LowerLeg_L", "l_ankle": "Foot_L", "l_ball": None,
    "l_toe1": "Toes_L", "l_toe": "END",
}  # fmt: skip
MIXAMO_NAMES = {
    k: (None if v is None else v if v == "END" else "mixamorig:" + v)
    for k, v in CGSPEED_NAMES.items()
}


def _mirror_name(name: str) -> str:
    for a, b in (("_L_", "_R_"), ("_L", "_R"), ("Left", "Right"), ("LFingers", "RFingers")):
        if a in name:
            return name.replace(a, b)
    return name


def _full_names(names: dict[str, str | None]) -> dict[str, str | None]:
    out = dict(names)
    for role, value in names.items():
        if role.startswith("l_"):
            out["r_" + role[2:]] = value if value in (None, "END") else _mirror_name(value)
    return out


def _file_rotation(up: str, yaw_deg: float) -> np.ndarray:
    """World (Y-up) -> file axes: a yaw about up, then Y-up or Z-up axes (proper)."""
    yaw = Rotation.from_euler("y", yaw_deg, degrees=True).as_matrix()
    axes = np.eye(3) if up == "y" else np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])
    return axes @ yaw


def _rig_bvh(
    names: dict[str, str | None],
    *,
    scale: float = 1.0,
    up: str = "y",
    yaw: float = 0.0,
    shift=(0.0, 0.0, 0.0),
    frames: list[dict[str, tuple[np.ndarray, float]]] | None = None,
    order_override: str | None = None,
) -> str:
    """A BVH text of the template skeleton in a rig's naming, units and axes.

    ``frames``: per frame, role -> (rotation axis in world/person axes, degrees).
    """
    names = _full_names(names)
    template = _template()
    rot = _file_rotation(up, yaw)
    kept = {r for r, n in names.items() if n is not None}

    def kept_parent(role: str) -> str | None:
        p = template[role][0]
        while p is not None and p not in kept:
            p = template[p][0]
        return p

    children: dict[str | None, list[str]] = {}
    for role in template:
        if role in kept:
            children.setdefault(kept_parent(role), []).append(role)
    order: list[str] = []
    lines = ["HIERARCHY"]

    def emit(role: str, depth: int) -> None:
        pad = "  " * depth
        parent = kept_parent(role)
        pos = rot @ template[role][1] * scale
        off = pos - (rot @ template[parent][1] * scale if parent else 0.0)
        if parent is None:
            off = np.zeros(3)
        if names[role] == "END":
            lines.extend([f"{pad}End Site", f"{pad}{{", f"{pad}  OFFSET {_f(off)}", f"{pad}}}"])
            return
        kind = "ROOT" if parent is None else "JOINT"
        o = order_override if (order_override and "Fore" in names[role]) else "ZXY"
        rots = " ".join(f"{a}rotation" for a in o)
        chans = (
            f"CHANNELS 6 Xposition Yposition Zposition {rots}"
            if parent is None
            else (f"CHANNELS 3 {rots}")
        )
        lines.extend([f"{pad}{kind} {names[role]}", f"{pad}{{", f"{pad}  OFFSET {_f(off)}"])
        lines.append(f"{pad}  {chans}")
        order.append(role)
        for child in children.get(role, []):
            emit(child, depth + 1)
        lines.append(f"{pad}}}")

    emit("root", 0)
    frames = frames or [{}]
    lines += ["MOTION", f"Frames: {len(frames)}", "Frame Time: 0.0333333"]
    root_pos = rot @ template["root"][1] * scale + np.asarray(shift) * scale
    for frame in frames:
        values: list[float] = []
        for role in order:
            if role == "root":
                values.extend(root_pos)
            axis_angle = frame.get(role)
            if axis_angle is None:
                values.extend([0.0, 0.0, 0.0])
            else:
                axis, deg = axis_angle
                r = Rotation.from_rotvec(np.radians(deg) * (rot @ np.asarray(axis, float)))
                values.extend(r.as_euler("ZXY", degrees=True))
        lines.append(" ".join(_f1(v) for v in values))
    return "\n".join(lines) + "\n"


def _f(v) -> str:
    return " ".join(f"{x:.9f}" for x in v)


def _f1(x: float) -> str:
    return f"{x:.9f}"


RIG_CASES = [
    ("cgspeed", CGSPEED_NAMES),
    ("cmu-original", CMU_ORIGINAL_NAMES),
    ("cc-base", CC_BASE_NAMES),
    ("game", GAME_NAMES),
    ("cgspeed", MIXAMO_NAMES),
]


@pytest.mark.parametrize(
    ("rig", "names"), RIG_CASES, ids=[c[0] for c in RIG_CASES[:4]] + ["mixamo"]
)
def test_rig_names_map_to_the_15_joints(tmp_path, rig, names):
    path = tmp_path / "clip.bvh"
    path.write_text(_rig_bvh(names, scale=100.0, up="z", yaw=35.0, shift=(2.0, 0.0, -1.0)))
    motion = bvh_motion(path)
    assert motion.meta["rig"] == rig
    assert motion.meta["units"] == "cm" and motion.meta["up"] == "z"
    expected = t_pose_joints(H)
    got = motion.joints[0]
    head = JOINT_INDEX["head"]
    others = [i for i in range(15) if i != head]
    # Every joint within 1 mm of the template; the head too where the rig gives a head top.
    np.testing.assert_allclose(got[others], expected[others], atol=1e-3)
    head_tol = 0.03 if rig == "cc-base" else 1e-3  # CC_Base: head top estimated
    np.testing.assert_allclose(got[head], expected[head], atol=head_tol)
    assert set(motion.extras) == {
        "head_top", "left_hand_tip", "right_hand_tip", "left_toe", "right_toe"
    }  # fmt: skip
    np.testing.assert_allclose(motion.extras["left_toe"][0], [_R["hh"], 0.0, 0.12 * H], atol=1e-3)
    np.testing.assert_allclose(motion.angles[0], [180, 180, 90, 90, 180, 180, 0, 0], atol=1e-6)


def test_cgspeed_neck_is_neck1_not_the_lower_neck(tmp_path):
    path = tmp_path / "clip.bvh"
    path.write_text(_rig_bvh(CGSPEED_NAMES))
    m = bvh_motion(path)
    neck = m.joints[0, JOINT_INDEX["neck"]]
    shoulders = m.joints[0, [JOINT_INDEX["left_shoulder"], JOINT_INDEX["right_shoulder"]]]
    assert 0.0 < neck[1] - shoulders[:, 1].mean() < 0.06


@pytest.mark.parametrize(
    ("unit", "scale"),
    [("m", 1.0), ("cm", 100.0), ("mm", 1000.0), ("inch", 1 / 0.0254), ("cmu", 0.45 / 0.0254)],
)
@pytest.mark.parametrize("up", ["y", "z"])
def test_units_and_up_axis_detected(tmp_path, unit, scale, up):
    path = tmp_path / "clip.bvh"
    path.write_text(_rig_bvh(CMU_ORIGINAL_NAMES, scale=scale, up=up, yaw=-120.0))
    motion = bvh_motion(path)
    assert motion.meta["units"] == unit
    assert motion.meta["up"] == up
    assert motion.meta["stature_m"] == pytest.approx(H, abs=0.01)
    np.testing.assert_allclose(motion.joints[0], t_pose_joints(H), atol=1e-3)


def test_detect_units_rejects_non_human_sizes():
    with pytest.raises(ValueError, match=r"cannot tell the units.*Pass scale="):
        detect_units(7.0, source="tiny.bvh")
    with pytest.raises(ValueError, match="has no height"):
        detect_units(0.0)


def test_unknown_rig_lists_missing_joints_and_names(tmp_path):
    names = dict(GAME_NAMES, l_elbow="Elbow_L", l_knee="Knee_L")
    path = tmp_path / "odd.bvh"
    path.write_text(_rig_bvh(names))
    with pytest.raises(ValueError, match=r"odd\.bvh: cannot map the skeleton") as info:
        bvh_motion(path)
    message = str(info.value)
    assert "closest rig 'game'" in message
    for joint in ("left_elbow", "right_elbow", "left_knee", "right_knee"):
        assert joint in message
    assert "Elbow_L" in message and "UpperArm_L" in message  # the file's own names
    # A custom mapping makes it work.
    custom = {
        "head": "Head", "neck": "Neck", "left_shoulder": "UpperArm_L",
        "right_shoulder": "UpperArm_R", "left_elbow": "Elbow_L", "right_elbow": "Elbow_R",
        "left_hand": "Hand_L", "right_hand": "Hand_R", "left_hip": "UpperLeg_L",
        "right_hip": "UpperLeg_R", "left_knee": "Knee_L", "right_knee": "Knee_R",
        "left_foot": "Foot_L", "right_foot": "Foot_R", "head_top": "Head/End Site",
    }  # fmt: skip
    m = bvh_motion(path, rig=custom)
    np.testing.assert_allclose(m.joints[0], t_pose_joints(H), atol=1e-2)


def test_rig_argument_errors():
    with pytest.raises(ValueError, match="The 'rig' parameter must be one of"):
        resolve_rig(["Hips"], rig="nope")
    with pytest.raises(ValueError, match="keys that are not joint or extra-point names"):
        resolve_rig(["Hips"], rig={"pelvis": "Hips"})


# --------------------------------------------------------------------------- angles


def test_hand_derived_angles_of_a_constructed_clip(tmp_path):
    """Rotations of known size about the person's own axes give known Table 1 angles."""
    left, up, fwd = np.eye(3)[0], np.eye(3)[1], np.eye(3)[2]
    theta, phi, kappa, psi = 37.0, 25.0, 62.0, 48.0
    frame = {
        "l_elbow": (up, theta),  # forearm swings forward in the horizontal plane
        "r_elbow": (up, -theta / 2),
        "l_shoulder": (fwd, -phi),  # left arm lowered in the frontal plane
        "r_shoulder": (fwd, phi / 2),  # right arm lowered
        "l_hip": (left, -psi),  # left thigh forward (flexion)
        "l_knee": (left, kappa),  # left shank backward
        "r_knee": (left, kappa / 2),
    }
    path = tmp_path / "angles.bvh"
    path.write_text(_rig_bvh(CGSPEED_NAMES, scale=100.0, up="z", yaw=70.0, frames=[{}, frame]))
    motion = bvh_motion(path)
    expected = [
        180 - theta, 180 - theta / 2, 90 - phi, 90 - phi / 2,
        180 - kappa, 180 - kappa / 2, psi, 0.0,
    ]  # fmt: skip
    np.testing.assert_allclose(motion.angles[1], expected, atol=0.5)
    np.testing.assert_allclose(motion.angles[1], expected, atol=1e-5)  # in fact exact


def _bvhio_joints(path: Path, names: dict[str, str], frames: list[int]) -> np.ndarray:
    """Independent FK: bvhio's world positions of the rig's nodes, as 15 joints.

    ``head`` and ``torso`` only matter through ``neck`` and the hips for the angles.
    """
    bvhio = pytest.importorskip("bvhio")
    root = bvhio.readAsHierarchy(str(path))
    nodes = {j.Name: j for j, _, _ in root.layout()}
    out = np.zeros((len(frames), 15, 3))
    for k, f in enumerate(frames):
        root.loadPose(f)
        for joint, node in names.items():
            out[k, JOINT_INDEX[joint]] = np.array(nodes[node].PositionWorld, dtype=float)
    out[:, JOINT_INDEX["torso"]] = 0.5 * (
        out[:, JOINT_INDEX["neck"]]
        + 0.5 * (out[:, JOINT_INDEX["left_hip"]] + out[:, JOINT_INDEX["right_hip"]])
    )
    out[:, JOINT_INDEX["head"]] = out[:, JOINT_INDEX["neck"]] + [0, 1, 0]
    return out


def _sides(d: dict[str, str], swap: tuple[str, str]) -> dict[str, str]:
    out = dict(d)
    for k, v in d.items():
        if k.startswith("left_"):
            out["right_" + k[5:]] = v.replace(*swap)
    return out


_CC_NODES = _sides(
    {
        "neck": "CC_Base_NeckTwist01",
        "left_shoulder": "CC_Base_L_Upperarm",
        "left_elbow": "CC_Base_L_Forearm",
        "left_hand": "CC_Base_L_Hand",
        "left_hip": "CC_Base_L_Thigh",
        "left_knee": "CC_Base_L_Calf",
        "left_foot": "CC_Base_L_Foot",
    },
    ("_L_", "_R_"),
)
_CMU_NODES = _sides(
    {
        "neck": "Neck",
        "left_shoulder": "LeftShoulder",
        "left_elbow": "LeftElbow",
        "left_hand": "LeftWrist",
        "left_hip": "LeftHip",
        "left_knee": "LeftKnee",
        "left_foot": "LeftAnkle",
    },
    ("Left", "Right"),
)


@pytest.mark.parametrize(
    ("relative", "nodes"),
    [("cmu/007_05.bvh", _CC_NODES), ("cmu-original-skeleton/131_03.bvh", _CMU_NODES)],
)
def test_angles_agree_with_bvhio(mocap_dir, relative, nodes):
    path = mocap_dir / relative
    motion = bvh_motion(path)
    dropped = motion.meta["dropped_leading_frames"]
    frames = list(range(dropped, dropped + len(motion), max(len(motion) // 25, 1)))
    reference = joint_angles(_bvhio_joints(path, nodes, frames))
    ours = motion.angles[[f - dropped for f in frames]]
    assert np.abs(ours - reference).max() < 0.5
