"""Joints the camera cannot see: the trunk continued out of the image, limbs held on it."""

from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from posedrift.skeleton import JOINT_INDEX, PART_INDEX, joint_angles, t_pose_joints
from posedrift.skeleton._unseen import (
    HELD_JOINTS,
    MIN_UPPER_TORSO_POINTS,
    continue_trunk,
    hold_limbs,
    trunk_frame,
)

J = JOINT_INDEX
NECK, TORSO, RIGHT_HIP, LEFT_HIP = J["neck"], J["torso"], J["right_hip"], J["left_hip"]
UPPER, LOWER = PART_INDEX["upper_torso"], PART_INDEX["lower_torso"]
ARMS = [J[n] for n in ("right_elbow", "left_elbow", "right_hand", "left_hand")]


def _bones(joints):
    from posedrift.skeleton import JOINT_PARENTS

    parents = np.array([max(p, 0) for p in JOINT_PARENTS])
    return np.linalg.norm(joints - joints[parents], axis=1)


def _pelvis(joints):
    return 0.5 * (joints[RIGHT_HIP] + joints[LEFT_HIP])


def _leaned(degrees):
    """A T-pose 2.5 m from the camera, turned ``degrees`` about the hips' line (towards
    the camera for positive angles)."""
    joints = t_pose_joints(1.75) + [0.0, 0.0, 2.5]
    pelvis = _pelvis(joints)
    turn = Rotation.from_rotvec(np.radians(degrees) * np.array([1.0, 0.0, 0.0])).as_matrix()
    return pelvis + (joints - pelvis) @ turn.T


def _torso_points(joints, visible=0.8):
    """A grid of points on a 25 cm wide slab along the trunk, from the pelvis up to
    ``visible`` of the way to the neck (the rest cut off by the image's edge), and
    where they are cut."""
    up, across, _ = trunk_frame(joints).T
    pelvis = _pelvis(joints)
    length = np.linalg.norm(joints[NECK] - pelvis)
    along, side = np.meshgrid(np.linspace(0.0, visible * length, 30), np.linspace(-0.125, 0.125, 8))
    along, side = along.ravel(), side.ravel()
    points = pelvis + along[:, None] * up + side[:, None] * across
    labels = np.where(along > 0.5 * length, UPPER, LOWER)
    exits = np.full((15, 3), np.nan)
    exits[UPPER] = pelvis + visible * length * up
    return points, labels, exits


def test_continue_trunk_follows_the_visible_torso():
    upright, leaned = _leaned(0.0), _leaned(20.0)
    bones = _bones(leaned)
    points, labels, exits = _torso_points(leaned)
    # The fit's neck and arms where the prediction left them (upright); the hips measured.
    joints = leaned.copy()
    moved = [J["head"], NECK, J["right_shoulder"], J["left_shoulder"], *ARMS]
    joints[moved] = upright[moved]
    measured = np.zeros(15, dtype=bool)
    measured[[RIGHT_HIP, LEFT_HIP, J["right_elbow"]]] = True
    out = continue_trunk(
        joints, measured, points, labels, previous=upright, exits=exits, bone_lengths=bones
    )
    # On the torso's axis at the trunk's length.
    pelvis = _pelvis(joints)
    trunk, truth = out[NECK] - pelvis, leaned[NECK] - pelvis
    cos = trunk @ truth / np.linalg.norm(trunk) / np.linalg.norm(truth)
    assert np.degrees(np.arccos(min(cos, 1.0))) < 0.01
    assert abs(np.linalg.norm(trunk) - 2.0 * bones[NECK]) < 1e-9
    shift = out[NECK] - joints[NECK]
    np.testing.assert_allclose(out[J["left_hand"]], joints[J["left_hand"]] + shift)
    np.testing.assert_array_equal(out[J["right_elbow"]], joints[J["right_elbow"]])  # measured
    np.testing.assert_allclose(out[TORSO], 0.5 * (out[NECK] + pelvis))
    np.testing.assert_array_equal(out[[RIGHT_HIP, LEFT_HIP]], joints[[RIGHT_HIP, LEFT_HIP]])


def test_continue_trunk_keeps_the_last_trunk_where_the_axis_turned_too_far():
    upright, leaned = _leaned(0.0), _leaned(60.0)
    bones = _bones(upright)
    points, labels, exits = _torso_points(leaned)  # 60 degrees from the last trunk
    joints = upright.copy()
    joints[NECK] += [0.0, 0.2, 0.0]  # the fit's neck 20 cm low
    out = continue_trunk(
        joints,
        np.zeros(15, dtype=bool),
        points,
        labels,
        previous=upright,
        exits=exits,
        bone_lengths=bones,
    )
    assert np.linalg.norm(out[NECK] - upright[NECK]) < 1e-9


def test_continue_trunk_leaves_a_seen_neck_or_an_uncut_torso_alone():
    upright, leaned = _leaned(0.0), _leaned(20.0)
    bones = _bones(leaned)
    points, labels, exits = _torso_points(leaned)
    unmeasured = np.zeros(15, dtype=bool)
    neck_seen = unmeasured.copy()
    neck_seen[NECK] = True

    def run(measured=unmeasured, labels=labels, exits=exits):
        return continue_trunk(
            upright, measured, points, labels, previous=upright, exits=exits, bone_lengths=bones
        )

    assert run(measured=neck_seen) is upright
    assert run(exits=np.full((15, 3), np.nan)) is upright
    few = labels.copy()
    few[np.flatnonzero(labels == UPPER)[MIN_UPPER_TORSO_POINTS - 1 :]] = LOWER
    assert run(labels=few) is upright
    assert run() is not upright  # (the case that does apply)


def _arms_raised(joints):
    """``joints`` with both arms raised 50 degrees and bent (a pose to hold)."""
    out = joints.copy()
    for side in ("right", "left"):
        s, e, h = (J[f"{side}_{n}"] for n in ("shoulder", "elbow", "hand"))
        turn = Rotation.from_rotvec(
            np.radians(50.0 if side == "right" else -50.0) * np.array([0.0, 0, 1.0])
        )
        out[[e, h]] = out[s] + turn.apply(out[[e, h]] - out[s])
        bend = Rotation.from_rotvec(np.radians(40.0) * np.array([1.0, 0, 0]))
        out[h] = out[e] + bend.apply(out[h] - out[e])
    return out


def test_hold_limbs_keeps_the_unseen_arms_angles_to_the_trunk():
    previous = _arms_raised(t_pose_joints(1.75)) + [0.1, -0.2, 2.6]
    # The body turned 30 degrees and leaned 10 and moved; the fit's arms left behind.
    turn = Rotation.from_euler("yx", [30.0, 10.0], degrees=True).as_matrix()
    truth = previous @ turn.T + [0.2, 0.05, -0.1]
    joints = truth.copy()
    joints[ARMS] = previous[ARMS]
    out_of_view = np.ones(15, dtype=bool)
    out_of_view[ARMS] = False
    out = hold_limbs(
        joints,
        np.zeros(15, dtype=bool),
        previous,
        in_view=out_of_view,
        previous_in_view=out_of_view,
    )
    np.testing.assert_allclose(out[ARMS], truth[ARMS], atol=1e-9)  # metres
    np.testing.assert_allclose(joint_angles(out), joint_angles(previous), atol=1e-6)  # degrees


def test_hold_limbs_leaves_seen_and_measured_joints_alone():
    previous = _arms_raised(t_pose_joints(1.75)) + [0.0, 0.0, 2.5]
    joints = previous + [0.05, 0.0, 0.0]
    joints[J["left_hand"]] += [0.0, 0.1, 0.0]  # moved by its own measurement
    seen = np.ones(15, dtype=bool)
    measured = np.zeros(15, dtype=bool)
    assert hold_limbs(joints, measured, previous, in_view=seen, previous_in_view=seen) is joints
    # Out of view but measured: kept; out of view and not measured: held.
    unseen = seen.copy()
    unseen[[J["left_hand"], J["right_hand"]]] = False
    measured[J["left_hand"]] = True
    out = hold_limbs(joints, measured, previous, in_view=unseen, previous_in_view=seen)
    np.testing.assert_array_equal(out[J["left_hand"]], joints[J["left_hand"]])
    hand, elbow = J["right_hand"], J["right_elbow"]
    np.testing.assert_allclose(out[hand], joints[elbow] + previous[hand] - previous[elbow])
    # Without a trunk there is no rotation to hold by.
    broken = joints.copy()
    broken[NECK] = _pelvis(broken)
    assert hold_limbs(broken, measured, previous, in_view=unseen, previous_in_view=seen) is broken
    assert set(HELD_JOINTS) == {"head", "right_elbow", "left_elbow", "right_hand", "left_hand"}
