import numpy as np
import pytest

from posedrift.skeleton import (
    ANGLE_NAMES,
    JOINT_INDEX,
    JOINT_NAMES,
    JOINT_PARENTS,
    PART_COLOURS,
    PART_NAMES,
    angles_dict,
    joint_angles,
    pelvis_centre,
    t_pose_joints,
)


def test_fifteen_joints_parts_and_distinct_colours():
    assert len(JOINT_NAMES) == 15 and len(PART_NAMES) == 15
    assert len(set(PART_COLOURS)) == 15
    assert JOINT_PARENTS[JOINT_INDEX["torso"]] == -1
    assert sum(p == -1 for p in JOINT_PARENTS) == 1


def test_t_pose_angles():
    angles = dict(zip(ANGLE_NAMES, joint_angles(t_pose_joints(1.8)), strict=True))
    for side in ("left", "right"):
        assert angles[f"{side}_elbow"] == pytest.approx(180.0, abs=1e-9)
        assert angles[f"{side}_knee"] == pytest.approx(180.0, abs=1e-9)
        assert angles[f"{side}_shoulder"] == pytest.approx(90.0, abs=1e-9)
        assert angles[f"{side}_hip"] == pytest.approx(0.0, abs=1e-9)


def test_torso_is_midpoint_of_neck_and_pelvis():
    j = t_pose_joints(1.6)
    expected = 0.5 * (j[JOINT_INDEX["neck"]] + pelvis_centre(j))
    np.testing.assert_allclose(j[JOINT_INDEX["torso"]], expected)


def test_hand_derived_angles_of_a_bent_arm_and_raised_thigh():
    j = t_pose_joints(1.75)
    # Bend the left forearm 90 degrees forward (+Z) at the elbow.
    elbow = j[JOINT_INDEX["left_elbow"]]
    forearm = np.linalg.norm(j[JOINT_INDEX["left_hand"]] - elbow)
    j[JOINT_INDEX["left_hand"]] = elbow + [0.0, 0.0, forearm]
    # Lift the right thigh 60 degrees forward, shank hanging straight down.
    hip = j[JOINT_INDEX["right_hip"]]
    thigh = np.linalg.norm(j[JOINT_INDEX["right_knee"]] - hip)
    knee = hip + thigh * np.array([0.0, -np.cos(np.radians(60)), np.sin(np.radians(60))])
    j[JOINT_INDEX["right_knee"]] = knee
    j[JOINT_INDEX["right_foot"]] = knee + [0.0, -0.4, 0.0]
    a = dict(zip(ANGLE_NAMES, joint_angles(j), strict=True))
    assert a["left_elbow"] == pytest.approx(90.0, abs=1e-9)
    assert a["right_hip"] == pytest.approx(60.0, abs=1e-9)
    assert a["right_knee"] == pytest.approx(120.0, abs=1e-9)
    assert a["left_shoulder"] == pytest.approx(90.0, abs=1e-9)


def test_angles_invariant_to_rigid_motion_and_units():
    rng = np.random.default_rng(0)
    j = t_pose_joints(1.7) + rng.normal(scale=0.05, size=(15, 3))
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    moved = 1000.0 * (j @ q.T) + [3.0, -2.0, 5.0]
    np.testing.assert_allclose(joint_angles(moved), joint_angles(j), atol=1e-9)


def test_batched_and_nan_handling():
    j = np.stack([t_pose_joints(1.7)] * 4)
    j[2, JOINT_INDEX["left_hand"]] = np.nan
    a = joint_angles(j)
    assert a.shape == (4, 8)
    assert np.isnan(a[2, ANGLE_NAMES.index("left_elbow")])
    assert angles_dict(a[2])["left_elbow"] is None
    assert np.isfinite(a[[0, 1, 3]]).all()


def test_wrong_shape_names_the_argument():
    with pytest.raises(ValueError, match="'joints'.*\\(\\.\\.\\., 15, 3\\)"):
        joint_angles(np.zeros((14, 3)))


def test_facing_yaw_follows_a_turn_about_the_vertical():
    from posedrift.skeleton import facing_yaw

    world = t_pose_joints(1.75)  # +Y up, facing +Z, the person's left at +X
    frames = []
    for yaw in (0.0, 30.0, 90.0, 150.0, 180.0, -60.0):
        a = np.radians(yaw)
        turn = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
        # Camera 3 m in front of the person, looking back at them (OpenCV axes).
        frames.append((world @ turn.T) * [1.0, -1.0, -1.0] + [0.0, 0.0, 3.0])
    got = facing_yaw(np.stack(frames))
    np.testing.assert_allclose(got, [0.0, 30.0, 90.0, 150.0, 180.0, 60.0], atol=1e-9)
    # Signed: these turns take the person's left side away from the camera (negative)
    # but the last, which brings it nearer.
    signed = facing_yaw(np.stack(frames), signed=True)
    np.testing.assert_allclose(signed[[1, 2, 3, 5]], [-30.0, -90.0, -150.0, 60.0], atol=1e-9)
    np.testing.assert_allclose(np.abs(signed), got, atol=1e-9)
    for joints, yaw in zip(frames, signed, strict=True):
        assert facing_yaw(joints, signed=True) == yaw  # one skeleton: the same value
        left, right = joints[JOINT_INDEX["left_hip"], 2], joints[JOINT_INDEX["right_hip"], 2]
        assert abs(yaw) in (0.0, 180.0) or (yaw > 0) == (left < right)
    unknown = np.full((15, 3), np.nan)
    assert np.isnan(facing_yaw(unknown)) and np.isnan(facing_yaw(unknown, signed=True))


def test_facing_yaw_of_one_skeleton_is_the_batched_value_to_the_last_bit():
    from posedrift.skeleton import facing_yaw

    rng = np.random.default_rng(0)
    skeletons = rng.normal(0.0, 0.5, (2000, 15, 3)) + [0.0, 0.0, 3.0]
    skeletons[::7, :, 1] = 0.0  # exact zeros where up's products vanish
    skeletons[::11, [JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]]] = 0.0  # at the camera
    skeletons[::13, JOINT_INDEX["left_shoulder"], 0] = np.nan
    batched = facing_yaw(skeletons)
    one = np.array([facing_yaw(s) for s in skeletons])
    np.testing.assert_array_equal(one, batched)  # NaN where the batch has NaN
    signed = np.array([facing_yaw(s, signed=True) for s in skeletons])
    np.testing.assert_array_equal(signed, facing_yaw(skeletons, signed=True))
    np.testing.assert_array_equal(np.abs(signed), batched)
    assert np.isnan(one).any() and np.isfinite(one).sum() > 1500
    # A skeleton level with the camera's centre (no horizontal direction to it): NaN.
    level = np.zeros((15, 3))
    level[JOINT_INDEX["left_shoulder"], 0] = 0.2
    assert np.isnan(facing_yaw(level)) and np.isnan(facing_yaw(level[None])[0])
