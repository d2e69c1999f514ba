"""Motion, resampling, the calibration T-pose, BVH clips in the world frame, procedural motion."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.skeleton import (
    EXTRA_POINT_NAMES,
    JOINT_INDEX,
    JOINT_PARENTS,
    SEGMENT_RATIOS,
    t_pose_joints,
)
from posedrift.synthetic import (
    Motion,
    bvh_motion,
    is_t_pose,
    procedural_motion,
    with_calibration_pose,
)
from posedrift.synthetic._procedural import SCRIPT_SECONDS

J = JOINT_INDEX
T_POSE_ANGLES = [180, 180, 90, 90, 180, 180, 0, 0]
_EXTRA_PARENT = {
    "head_top": "head",
    "left_hand_tip": "left_hand",
    "right_hand_tip": "right_hand",
    "left_toe": "left_foot",
    "right_toe": "right_foot",
}


def _bone_lengths(m: Motion) -> np.ndarray:
    """``(T, 14 + extras)`` lengths of the JOINT_PARENTS bones and extra bones."""
    child = [i for i, p in enumerate(JOINT_PARENTS) if p >= 0]
    parent = [JOINT_PARENTS[i] for i in child]
    lengths = [np.linalg.norm(m.joints[:, child] - m.joints[:, parent], axis=-1)]
    for name, value in sorted(m.extras.items()):
        lengths.append(
            np.linalg.norm(value - m.joints[:, J[_EXTRA_PARENT[name]]], axis=-1)[:, None]
        )
    return np.concatenate(lengths, axis=1)


def _facing(j: np.ndarray) -> np.ndarray:
    """Horizontal unit forward of one frame (right-to-left x up)."""
    r2l = j[J["left_hip"]] - j[J["right_hip"]] + j[J["left_shoulder"]] - j[J["right_shoulder"]]
    f = np.cross(r2l, [0.0, 1.0, 0.0])
    f[1] = 0.0
    return f / np.linalg.norm(f)


# --------------------------------------------------------------------------- Motion


def test_motion_validation():
    still = np.stack([t_pose_joints()] * 4)
    with pytest.raises(
        ValueError, match=r"'joints' argument of Motion must have shape \(T, 15, 3\)"
    ):
        Motion(still[:, :14])
    bad = still.copy()
    bad[2, 3, 1] = np.nan
    with pytest.raises(ValueError, match="must be finite. Got NaN or infinity at frame 2"):
        Motion(bad)
    with pytest.raises(ValueError, match="takes keys in"):
        Motion(still, {"nose": np.zeros((4, 3))})
    with pytest.raises(ValueError, match=r"Motion extra 'head_top' must be a finite \(4, 3\)"):
        Motion(still, {"head_top": np.zeros((3, 3))})
    with pytest.raises(ValueError, match="The 'fps' parameter of Motion must be a float in"):
        Motion(still, fps=0.0)
    m = Motion(still, {"head_top": np.zeros((4, 3))}, 30.0, "x")
    assert len(m) == 4 and m.duration == pytest.approx(0.1)
    with pytest.raises(ValueError, match="read-only"):
        m.joints[0, 0, 0] = 1.0


def test_resample_halves_exactly_and_interpolates_linearly():
    t = np.arange(11) / 60.0
    joints = t_pose_joints()[None] + (t[:, None, None] * np.array([1.0, 2.0, 3.0]))
    m = Motion(joints, {"head_top": joints[:, 0]}, 60.0, "line")
    half = m.resample(30.0)
    assert len(half) == 6 and half.fps == 30.0
    np.testing.assert_allclose(half.joints, joints[::2], atol=1e-12)
    np.testing.assert_allclose(half.extras["head_top"], joints[::2, 0], atol=1e-12)
    third = m.resample(45.0)  # 0, 1.333, 2.667 ... source frames: linear motion stays exact
    expected = t_pose_joints()[None] + (np.arange(len(third)) / 45.0)[:, None, None] * [1, 2, 3]
    np.testing.assert_allclose(third.joints, expected, atol=1e-12)
    assert m.resample(60.0) is m
    with pytest.raises(ValueError, match="'fps' parameter of Motion.resample"):
        m.resample(-1.0)


def test_resample_keeps_frame_zero_and_ends_on_or_before_the_last():
    m = procedural_motion(seconds=3.0, fps=120.0)
    r = m.resample(30.0)
    assert len(r) == 91
    np.testing.assert_array_equal(r.joints[0], m.joints[0])
    np.testing.assert_allclose(r.joints[-1], m.joints[-1], atol=1e-12)
    np.testing.assert_allclose(r.angles, m.angles[::4], atol=1e-9)


# --------------------------------------------------------------------------- calibration


def test_is_t_pose():
    assert is_t_pose(t_pose_joints(1.6))
    arms_down = procedural_motion(seconds=2.0).joints[-1]
    assert not is_t_pose(arms_down)


def test_calibration_identity_when_frame_zero_is_a_t_pose():
    m = procedural_motion(seconds=4.0)
    assert with_calibration_pose(m) is m


def test_calibration_pose_blends_with_fixed_bone_lengths():
    source = procedural_motion(seconds=16.0)
    clip = Motion(
        source.joints[330:],  # starts with the arms crossed
        {k: v[330:] for k, v in source.extras.items()},
        30.0,
        "crossed",
    )
    out = with_calibration_pose(clip, blend_seconds=1.0)
    assert len(out) == len(clip) + 30 and out.meta["calibration_frames"] == 30
    np.testing.assert_allclose(out.angles[0], T_POSE_ANGLES, atol=1e-6)
    assert is_t_pose(out.joints[0])
    np.testing.assert_array_equal(out.joints[30:], clip.joints)
    # Bone lengths (skeleton and extras) stay those of the clip's frame 0 throughout.
    lengths = _bone_lengths(out)
    np.testing.assert_allclose(lengths[:31], np.broadcast_to(lengths[30], (31, lengths.shape[1])),
                               atol=1e-9)  # fmt: skip
    # Same place and facing; on the floor; no jump into the clip.
    pelvis = lambda j: 0.5 * (j[J["left_hip"]] + j[J["right_hip"]])  # noqa: E731
    np.testing.assert_allclose(pelvis(out.joints[0])[[0, 2]], pelvis(clip.joints[0])[[0, 2]])
    np.testing.assert_allclose(_facing(out.joints[0]), _facing(clip.joints[0]), atol=1e-9)
    assert min(out.joints[0, J["left_foot"], 1], out.joints[0, J["right_foot"], 1]) == (
        pytest.approx(0.039 * 1.75, abs=1e-9)
    )
    steps = np.linalg.norm(np.diff(out.joints[:32], axis=0), axis=-1).max()
    assert steps < 0.1  # metres per frame at 30 fps: under 3 m/s


def test_calibration_pose_of_a_bent_frame_faces_the_same_way():
    source = procedural_motion(seconds=SCRIPT_SECONDS)
    k = int(26.4 * 30)  # bent forward at the waist, arms hanging
    clip = Motion(source.joints[k:], {}, 30.0)
    out = with_calibration_pose(clip, blend_seconds=0.5)
    assert out.meta["calibration_frames"] == 15
    np.testing.assert_allclose(out.angles[0], T_POSE_ANGLES, atol=1e-6)
    np.testing.assert_allclose(_facing(out.joints[0]), _facing(clip.joints[0]), atol=1e-9)
    with pytest.raises(ValueError, match="'blend_seconds' parameter of with_calibration_pose"):
        with_calibration_pose(clip, blend_seconds=0.0)
    with pytest.raises(ValueError, match="must be a Motion"):
        with_calibration_pose(clip.joints)


# --------------------------------------------------------------------------- procedural


def test_procedural_motion_script():
    m = procedural_motion()
    assert m.fps == 30.0 and 20.0 <= m.duration <= 31.0
    assert m.duration == pytest.approx(SCRIPT_SECONDS, abs=1 / 30)
    assert set(m.extras) == set(EXTRA_POINT_NAMES)
    np.testing.assert_allclose(m.angles[0], T_POSE_ANGLES, atol=1e-9)
    np.testing.assert_allclose(m.joints[0], t_pose_joints(1.75), atol=1e-12)
    a = m.angles
    assert a[:, 2:4].max() > 165  # arms over the head
    assert a[:, 0:2].min() < 75  # elbow curls
    assert a[:, 4:6].min() < 90 and a[:, 6:8].max() > 100  # squat
    assert a[:, 6].max() > 75 and a[:, 7].max() > 55  # kicks
    # Arms crossing in front of the chest: each hand past the body's midline.
    left_x = m.joints[:, J["left_hand"], 0]
    right_x = m.joints[:, J["right_hand"], 0]
    assert np.any((left_x < -0.1) & (right_x > 0.1))
    # Leg crossing: the right ankle left of the midline while standing.
    assert m.joints[:, J["right_foot"], 0].max() > 0.05
    # Quarter turn: the person ends facing +X (their former left).
    np.testing.assert_allclose(_facing(m.joints[-1]), [1.0, 0.0, 0.0], atol=1e-6)


def test_procedural_motion_is_physical():
    h = 1.8
    m = procedural_motion(height=h, seconds=SCRIPT_SECONDS)
    lengths = _bone_lengths(m)
    assert np.ptp(lengths, axis=0).max() < 1e-9
    r = SEGMENT_RATIOS
    column = [i for i, p in enumerate(JOINT_PARENTS) if p >= 0].index
    np.testing.assert_allclose(
        lengths[0, [column(J["left_elbow"]), column(J["left_hand"]), column(J["left_knee"])]],
        [r["upper_arm"] * h, r["forearm"] * h, r["thigh"] * h],
    )
    feet = m.joints[:, [J["left_foot"], J["right_foot"]]]
    np.testing.assert_allclose(feet[:, :, 1].min(axis=1), r["ankle_height"] * h, atol=1e-12)
    for name in ("left_toe", "right_toe"):
        assert m.extras[name][:, 1].min() >= -1e-9  # toes never below the floor
    speed = np.linalg.norm(np.diff(m.joints, axis=0), axis=-1).max() * m.fps
    assert speed < 6.0  # m/s: smooth, no jumps
    # Feet that stay on the floor do not slide (a turn in place pivots them a little).
    on = np.abs(feet[:, :, 1] - r["ankle_height"] * h) < 1e-6
    slide = np.linalg.norm(np.diff(feet[:, :, [0, 2]], axis=0), axis=-1)
    grounded = on[1:] & on[:-1]
    arms_only = slice(0, int(14.0 * 30))  # arm moves: feet exactly still
    assert slide[arms_only][grounded[arms_only]].max() < 1e-9
    squat = slice(int(21.4 * 30), int(25.9 * 30))
    assert slide[squat][grounded[squat]].max() < 1e-9


def test_procedural_motion_is_deterministic_and_scales():
    a = procedural_motion(seconds=5.0)
    b = procedural_motion(seconds=5.0)
    np.testing.assert_array_equal(a.joints, b.joints)
    c = procedural_motion(seconds=5.0, height=1.5, fps=15.0)
    np.testing.assert_allclose(c.joints, a.joints[::2] * (1.5 / 1.75), atol=1e-12)
    longer = procedural_motion(seconds=2 * SCRIPT_SECONDS)
    np.testing.assert_allclose(_facing(longer.joints[-1]), [0.0, 0.0, -1.0], atol=1e-6)
    with pytest.raises(ValueError, match="'height' parameter of procedural_motion"):
        procedural_motion(height=-1.0)


# --------------------------------------------------------------------------- development clips


def test_development_clips_load_map_and_sit_in_the_world_frame(mocap_dir):
    paths = sorted(mocap_dir.glob("*/*.bvh"))
    assert len(paths) == 30
    for path in paths:
        m = bvh_motion(path)
        original = path.parent.name == "cmu-original-skeleton"
        assert m.meta["rig"] == ("cmu-original" if original else "cc-base"), path
        assert m.meta["units"] == ("cmu" if original else "cm"), path
        assert m.meta["up"] == "y", path  # both sets are Y-up after their root rotations
        assert m.fps == (120.0 if original else 60.0)
        assert 1.4 < m.meta["stature_m"] < 2.0, path
        assert not m.meta["mirrored"], path
        j0 = m.joints[0]
        pelvis = 0.5 * (j0[J["left_hip"]] + j0[J["right_hip"]])
        np.testing.assert_allclose(pelvis[[0, 2]], 0.0, atol=1e-9)
        np.testing.assert_allclose(_facing(j0), [0.0, 0.0, 1.0], atol=1e-9)
        assert j0[J["left_hip"], 0] > j0[J["right_hip"], 0]  # the person's left is +X
        # Floor: the lower ankle of frame 0 at 3.9 % of stature, or a toe on the floor.
        lowest = np.minimum(m.extras["left_toe"][:, 1], m.extras["right_toe"][:, 1])
        assert lowest[0] >= -1e-9 and np.percentile(lowest, 5) >= -1e-9
        if m.name == "001_14":  # starts hanging from the monkey bars: the floor is below
            assert lowest[0] > 1.0 and np.percentile(lowest, 5) < 0.05
        # Toes point forward (per frame, relative to the body).
        toes = m.extras["left_toe"] - m.joints[:, J["left_foot"]]
        r2l = m.joints[:, J["left_hip"]] - m.joints[:, J["right_hip"]]
        fwd = np.cross(r2l, [0.0, 1.0, 0.0])
        assert np.median(np.sum(toes * fwd, axis=1)) > 0, path
        # The head is above the neck, the neck between and above the shoulders.
        assert np.median(m.joints[:, J["head"], 1] - m.joints[:, J["neck"], 1]) > 0.05
        sh = m.joints[:, [J["left_shoulder"], J["right_shoulder"]], 1].mean(axis=1)
        assert 0.0 < np.median(m.joints[:, J["neck"], 1] - sh) < 0.1, path
        # No jumps: the first frames flow (a detached rest pose was dropped).
        step = np.linalg.norm(np.diff(m.joints[:10], axis=0), axis=-1).max() * m.fps
        assert step < 20.0, path
        assert np.all(np.isfinite(m.angles))


def test_detached_rest_frame_is_dropped_and_calibration_added(mocap_dir):
    m = bvh_motion(mocap_dir / "cmu" / "007_03.bvh")
    assert m.meta["dropped_leading_frames"] == 1  # a T-pose 2.6 m from the walk
    assert not is_t_pose(m.joints[0])
    c = with_calibration_pose(m.resample(30.0))
    assert is_t_pose(c.joints[0]) and c.meta["calibration_frames"] == 30
    lengths = _bone_lengths(c)
    np.testing.assert_allclose(lengths[:31], np.broadcast_to(lengths[30], (31, lengths.shape[1])),
                               atol=1e-9)  # fmt: skip
