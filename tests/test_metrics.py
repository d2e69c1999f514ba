"""Metrics of Table 1 and ITOP against hand-computed values."""

import numpy as np
import pytest

from posedrift.camera import camera_preset, project
from posedrift.evaluation import (
    angle_agreement,
    angle_errors,
    angles_in_view,
    angles_seen,
    failed_frames,
    fill_forward,
    joints_seen,
    map_at,
    markdown_table,
    mpjpe_mm,
)
from posedrift.skeleton import (
    ANGLE_JOINTS,
    ANGLE_NAMES,
    JOINT_INDEX,
    JOINT_NAMES,
    joint_angles,
    t_pose_joints,
)
from posedrift.synthetic import build_sequence, procedural_motion


def test_angle_errors_hand_computed():
    ref = np.array([[90.0] * 8, [100.0] * 8, [110.0] * 8])
    est = ref.copy()
    est[:, 0] = [95.0, 90.0, 110.0]  # |5|, |-10|, 0 -> 5
    est[1, 3] = np.nan  # right_shoulder: frames 0 and 2 only -> 0
    est[:, 7] = ref[:, 7] + 3.0  # right_hip: 3
    out = angle_errors(est, ref)
    assert out["left_elbow"] == pytest.approx(5.0)
    assert out["right_shoulder"] == pytest.approx(0.0)
    assert out["right_hip"] == pytest.approx(3.0)
    assert out["mean"] == pytest.approx((5.0 + 3.0) / 8)
    assert list(out) == [*ANGLE_NAMES, "mean"]


def test_angle_errors_identity_and_unknown():
    ref = np.random.default_rng(0).uniform(0, 180, (10, 8))
    assert angle_errors(ref, ref)["mean"] == 0.0
    est = ref.copy()
    est[:, 2] = np.nan
    out = angle_errors(est, ref)
    assert out["left_shoulder"] is None
    assert out["mean"] == 0.0


def test_mpjpe_and_map_hand_computed():
    ref = np.tile(t_pose_joints(1.75), (4, 1, 1))
    est = ref.copy()
    est[0, :, 0] += 0.05  # 50 mm, within 10 cm
    est[1, :, 1] += 0.20  # 200 mm, outside
    est[2, 3] = np.nan  # one unknown joint: left out
    # frames 0..3: 15 x 50 + 15 x 200 + 14 x 0 + 15 x 0 over 59 pairs
    assert mpjpe_mm(est, ref) == pytest.approx((15 * 50 + 15 * 200) / 59)
    # every joint: 1 miss in 4 frames, except left_shoulder: 1 miss in 3
    expected = (14 * 0.75 + 2 / 3) / 15
    assert map_at(est, ref) == pytest.approx(expected)
    assert map_at(est, ref, threshold=0.3) == pytest.approx(1.0)
    assert mpjpe_mm(ref, ref) == 0.0 and map_at(ref, ref) == 1.0


def test_failed_frames_and_fill_forward():
    joints = np.tile(t_pose_joints(1.75), (4, 1, 1))
    joints[0] = np.nan
    joints[2] = np.nan
    joints[3, :, 0] += 0.1
    assert failed_frames(joints).tolist() == [True, False, True, False]
    filled = fill_forward(joints)
    assert np.isnan(filled[0]).all()
    np.testing.assert_array_equal(filled[2], joints[1])
    np.testing.assert_array_equal(filled[3], joints[3])
    # angles of a filled frame are those of the pose it copies
    np.testing.assert_allclose(joint_angles(filled[2]), joint_angles(joints[1]))


@pytest.mark.parametrize(
    ("est", "ref", "match"),
    [
        (np.zeros((3, 7)), np.zeros((3, 7)), "must have shape \\(T, 8\\)"),
        (np.zeros((3, 8)), np.zeros((4, 8)), "same number of frames"),
    ],
)
def test_angle_errors_rejects_bad_shapes(est, ref, match):
    with pytest.raises(ValueError, match=match):
        angle_errors(est, ref)


def test_angle_agreement_identity_is_no_bias_and_no_spread():
    ref = np.random.default_rng(0).uniform(0.0, 180.0, (50, 8))
    for row in angle_agreement(ref.copy(), ref).values():
        assert row == {
            "bias_deg": 0.0,
            "sd_deg": 0.0,
            "loa_low_deg": 0.0,
            "loa_high_deg": 0.0,
            "frames": 50,
        }


def test_angle_agreement_recovers_a_known_offset_and_scatter():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0.0, 180.0, (20_000, 8))
    diff = 2.0 + 3.0 * rng.standard_normal(ref.shape)
    est = ref + diff
    est[:10, 5] = np.nan  # left out, not counted
    out = angle_agreement(est, ref)
    for k, name in enumerate(ANGLE_NAMES):
        row = out[name]
        assert row["bias_deg"] == pytest.approx(2.0, abs=0.1)  # 4.5 standard errors
        assert row["sd_deg"] == pytest.approx(3.0, abs=0.1)
        d = diff[np.isfinite(est[:, k]), k]
        inside = np.mean((d >= row["loa_low_deg"]) & (d <= row["loa_high_deg"]))
        assert inside == pytest.approx(0.95, abs=0.01)
    assert out["right_knee"]["frames"] == 20_000 - 10
    assert out["left_knee"]["frames"] == 20_000


def test_angle_agreement_needs_two_frames_and_the_right_shape():
    ref = np.full((3, 8), 90.0)
    est = ref.copy()
    est[1:, 2] = np.nan  # one frame left for the left shoulder
    row = angle_agreement(est, ref)["left_shoulder"]
    assert row["frames"] == 1 and row["bias_deg"] is None and row["loa_high_deg"] is None
    with pytest.raises(ValueError, match="angle_agreement must have shape \\(T, 8\\)"):
        angle_agreement(np.zeros((3, 7)), np.zeros((3, 7)))


def test_joint_metrics_reject_bad_input():
    with pytest.raises(ValueError, match="must have shape \\(T, 15, 3\\)"):
        mpjpe_mm(np.zeros((2, 14, 3)), np.zeros((2, 14, 3)))
    with pytest.raises(ValueError, match="positive distance"):
        map_at(np.zeros((2, 15, 3)), np.zeros((2, 15, 3)), threshold=0.0)


def test_markdown_table_layout():
    row = {
        "angle_error_deg": {**dict.fromkeys(ANGLE_NAMES, 2.0), "mean": 2.0},
        "mpjpe_mm": 61.25,
        "map_10cm": 0.8,
        "label_accuracy": None,
        "frames_per_second": 12.0,
        "failed_frames": 3,
    }
    text = markdown_table(
        {"protocol": "synthetic", "frames": 5, "sequences": ["x"], "methods": {"cpd": row}}
    )
    lines = text.splitlines()
    assert lines[0].startswith("| Method | L elbow | R elbow | L shoulder | R shoulder | L knee")
    assert "| cpd | 2.00 |" in lines[2] and "| 61.2 | 0.800 | 12.0 | 3 |" in lines[2]
    assert any("paper: its proposed method (CPD)" in line and "*6.26*" in line for line in lines)
    assert "not comparable" in text


def test_drift_compares_the_first_and_last_hundred_frames():
    from posedrift.evaluation._harness import _drift

    ref = np.full((250, 8), 90.0)
    est = ref.copy()
    est[:100] += 1.0
    est[150:] -= 3.0
    assert _drift(est, ref) == {"first_100_deg": 1.0, "last_100_deg": 3.0}
    assert _drift(est[:199], ref[:199]) == {}


def test_angles_in_view_needs_every_joint_of_the_angle_in_the_image():
    kinect = camera_preset("kinect1-qvga")
    facing = t_pose_joints(1.75) * [1, -1, -1] + [0, 0.9, 3.0]  # 2.5 m x 3.4 m in view
    assert angles_in_view(facing[None], kinect).all()  # identity: the whole person in view
    frames = np.repeat(facing[None], 4, axis=0)
    frames[1, JOINT_INDEX["left_hand"], 0] = 2.0  # 350 px right of the image centre
    frames[2, JOINT_INDEX["neck"], 2] = -1.0  # behind the camera
    frames[3, JOINT_INDEX["right_foot"]] = np.nan
    seen = angles_in_view(frames, kinect)
    assert seen[0].all()
    assert seen[1].tolist() == [name != "left_elbow" for name in ANGLE_NAMES]
    # The neck sets the trunk's axis: every shoulder and hip angle needs it.
    assert seen[2].tolist() == [name in ("left_elbow", "right_elbow", "left_knee", "right_knee")
                                for name in ANGLE_NAMES]  # fmt: skip
    assert seen[3].tolist() == [name != "right_knee" for name in ANGLE_NAMES]
    assert all("neck" in ANGLE_JOINTS[a] for a in ANGLE_NAMES if a.endswith(("shoulder", "hip")))
    with pytest.raises(ValueError, match="angles_in_view"):
        angles_in_view(facing, kinect)


@pytest.fixture(scope="module")
def t_pose_frame():
    """The built-in motion's first frame: the renderer's T-pose, facing the camera."""
    sequence = build_sequence(procedural_motion(), n_frames=1, rng=0)
    return sequence.reference.joints[0], sequence.frames[0].depth, sequence.frames[0].intrinsics


def _covered(depth, intrinsics, joint, in_front):
    """``depth`` with a 7 x 7 pixel board ``in_front`` metres before ``joint``."""
    u, v = np.rint(project(joint[None], intrinsics)[0]).astype(int)
    out = depth.copy()
    out[v - 3 : v + 4, u - 3 : u + 4] = joint[2] - in_front
    return out


def test_every_joint_of_a_rendered_t_pose_is_seen(t_pose_frame):
    joints, depth, camera = t_pose_frame
    assert joints_seen(joints[None], [depth], camera).all()  # identity
    assert angles_seen(joints[None], [depth], camera).all()
    # The joints lie under the body's surface: with no tolerance the deep ones are hidden.
    bare = joints_seen(joints[None], [depth], camera, tolerance=0.0)[0]
    assert not bare[[JOINT_INDEX[n] for n in ("torso", "right_hip", "left_hip", "head")]].any()


def test_a_joint_behind_something_30_cm_in_front_is_hidden(t_pose_frame):
    joints, depth, camera = t_pose_frame
    elbow = joints[JOINT_INDEX["left_elbow"]]
    hidden = joints_seen(joints[None], [_covered(depth, camera, elbow, 0.30)], camera)[0]
    assert hidden.tolist() == [name != "left_elbow" for name in JOINT_NAMES]
    angles = angles_seen(joints[None], [_covered(depth, camera, elbow, 0.30)], camera)[0]
    assert angles.tolist() == [name not in ("left_elbow", "left_shoulder") for name in ANGLE_NAMES]
    # 10 cm in front is within the tolerance (a joint's own flesh), as is nothing at all.
    assert joints_seen(joints[None], [_covered(depth, camera, elbow, 0.10)], camera).all()
    assert joints_seen(joints[None], [np.zeros_like(depth)], camera).all()
    assert joints_seen(joints[None], [np.full_like(depth, np.nan)], camera).all()


def test_joints_seen_needs_the_joint_in_the_image(t_pose_frame):
    joints, depth, camera = t_pose_frame
    frames = np.repeat(joints[None], 3, axis=0)
    frames[1, JOINT_INDEX["left_hand"], 0] = 5.0  # far right of the image
    frames[2, JOINT_INDEX["neck"]] = np.nan
    seen = joints_seen(frames, [depth] * 3, camera)
    np.testing.assert_array_equal(angles_seen(frames, [depth] * 3, camera), _per_angle(seen))
    np.testing.assert_array_equal(
        angles_seen(frames, [depth] * 3, camera) & angles_in_view(frames, camera),
        angles_seen(frames, [depth] * 3, camera),
    )
    assert seen[1].tolist() == [name != "left_hand" for name in JOINT_NAMES]
    assert seen[2].tolist() == [name != "neck" for name in JOINT_NAMES]


def _per_angle(seen):
    return np.stack(
        [seen[:, [JOINT_INDEX[j] for j in ANGLE_JOINTS[a]]].all(axis=1) for a in ANGLE_NAMES],
        axis=1,
    )


def test_a_body_turned_side_on_hides_its_far_leg():
    sequence = build_sequence(procedural_motion(), n_frames=1, rng=0, facing=90.0)
    joints, camera = sequence.reference.joints, sequence.frames[0].intrinsics
    seen = joints_seen(joints, [f.depth for f in sequence.frames], camera)[0]
    for joint in ("hip", "knee", "foot"):
        near, far = sorted(
            (f"left_{joint}", f"right_{joint}"), key=lambda n: joints[0, JOINT_INDEX[n], 2]
        )
        assert seen[JOINT_INDEX[near]] and not seen[JOINT_INDEX[far]]
    # In a T-pose side-on the arms lie along the camera's ray: the near arm hides the far one.
    far = (
        "left"
        if joints[0, JOINT_INDEX["left_hand"], 2] > joints[0, JOINT_INDEX["right_hand"], 2]
        else "right"
    )
    assert not seen[[JOINT_INDEX[f"{far}_{n}"] for n in ("shoulder", "elbow", "hand")]].any()


def test_joints_seen_rejects_mismatched_depth(t_pose_frame):
    joints, depth, camera = t_pose_frame
    with pytest.raises(ValueError, match="one image per reference frame"):
        joints_seen(joints[None], [depth, depth], camera)
    with pytest.raises(ValueError, match="Depth image 0.*shape"):
        joints_seen(joints[None], [depth[:10]], camera)
    with pytest.raises(ValueError, match="tolerance"):
        joints_seen(joints[None], [depth], camera, tolerance=-0.1)
