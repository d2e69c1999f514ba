"""Joint conventions: body frame, conversion and fitting, against constructed truth."""

import numpy as np
import pytest

from posedrift.skeleton import (
    CONVENTIONS,
    JOINT_INDEX,
    body_frame,
    fit_convention,
    t_pose_joints,
    to_convention,
)


def _rotation(yaw_deg: float, pitch_deg: float) -> np.ndarray:
    a, b = np.radians(yaw_deg), np.radians(pitch_deg)
    ry = np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])
    rx = np.array([[1, 0, 0], [0, np.cos(b), -np.sin(b)], [0, np.sin(b), np.cos(b)]])
    return rx @ ry


def _posed(n: int, rng: np.random.Generator) -> np.ndarray:
    """T-poses of different statures, turned, tilted and moved."""
    out = []
    for _ in range(n):
        joints = t_pose_joints(rng.uniform(1.5, 1.95))
        rot = _rotation(rng.uniform(-180, 180), rng.uniform(-20, 20))
        out.append(joints @ rot.T + rng.uniform(-1, 1, 3))
    return np.stack(out)


def test_body_frame_of_a_t_pose():
    axes, trunk = body_frame(t_pose_joints(1.75))  # world: +X the person's left, +Y up
    np.testing.assert_allclose(axes, np.eye(3), atol=1e-12)
    j = t_pose_joints(1.75)
    pelvis = 0.5 * (j[JOINT_INDEX["left_hip"]] + j[JOINT_INDEX["right_hip"]])
    assert trunk == pytest.approx(np.linalg.norm(j[JOINT_INDEX["neck"]] - pelvis))


def test_native_is_the_identity_and_kinect_moves_joints():
    joints = _posed(4, np.random.default_rng(0))
    np.testing.assert_array_equal(to_convention(joints, "native"), joints)
    moved = to_convention(joints, "kinect")
    shift = np.linalg.norm(moved - joints, axis=-1)
    assert 0.0 < shift.max() < 0.15  # centimetres, not metres
    assert CONVENTIONS["kinect"].shape == (15, 3)


def test_conversion_turns_with_the_body():
    joints = t_pose_joints(1.8)
    rot = _rotation(130.0, 10.0)
    turned_then_moved = to_convention(joints @ rot.T + [0.3, 0.0, 2.5], "kinect")
    moved_then_turned = to_convention(joints, "kinect") @ rot.T + [0.3, 0.0, 2.5]
    np.testing.assert_allclose(turned_then_moved, moved_then_turned, atol=1e-12)


def test_fit_recovers_known_offsets_in_millimetres():
    rng = np.random.default_rng(1)
    truth = rng.normal(scale=0.05, size=(15, 3))
    est = _posed(50, rng)
    axes, trunk = body_frame(est)
    ref = est + np.einsum("tab,ja->tjb", axes, truth) * trunk[:, None, None]
    ref[3] = np.nan  # a frame without reference is ignored
    fitted = fit_convention(est, ref)
    np.testing.assert_allclose(fitted, truth, atol=1e-9)
    # Identity: a reference equal to the estimate needs no offset.
    np.testing.assert_allclose(fit_convention(est, est), 0.0, atol=1e-12)


def test_bad_input_is_named():
    with pytest.raises(ValueError, match="Unknown joint convention 'vicon'"):
        to_convention(t_pose_joints(1.7), "vicon")
    with pytest.raises(ValueError, match=r"\(\.\.\., 15, 3\)"):
        to_convention(np.zeros((14, 3)))
    with pytest.raises(ValueError, match="both be"):
        fit_convention(np.zeros((2, 15, 3)), np.zeros((3, 15, 3)))
    with pytest.raises(ValueError, match="at least one frame"):
        fit_convention(np.full((2, 15, 3), np.nan), np.zeros((2, 15, 3)))
