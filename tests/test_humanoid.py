"""sample_humanoid: a capsule body posed by 15 joints."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.points import sample_humanoid
from posedrift.skeleton import JOINT_INDEX, t_pose_joints


def test_shape_extent_and_determinism():
    joints = t_pose_joints(1.75)
    pts = sample_humanoid(joints, 2000, rng=0)
    assert pts.shape == (2000, 3) and np.all(np.isfinite(pts))
    # a 1.75 m person: feet near the floor, head top near 1.75 m, arm span ~ stature
    assert -0.02 < pts[:, 1].min() < 0.03
    assert 1.68 < pts[:, 1].max() < 1.80
    assert 1.6 < np.ptp(pts[:, 0]) < 2.1
    np.testing.assert_array_equal(pts, sample_humanoid(joints, 2000, rng=0))
    assert not np.array_equal(pts, sample_humanoid(joints, 2000, rng=1))


def test_points_lie_on_the_skin_near_the_joints():
    joints = t_pose_joints(1.75)
    pts = sample_humanoid(joints, 3000, rng=2)
    # every joint has surface points within 15 cm, and no point is far from the skeleton
    d = np.linalg.norm(pts[:, None, :] - joints[None, :, :], axis=2)
    assert d.min(axis=0).max() < 0.15
    assert d.min(axis=1).max() < 0.35
    # the head sphere: points near the head joint lie on a ~11 cm radius sphere
    head = joints[JOINT_INDEX["head"]]
    near = np.linalg.norm(pts - head, axis=1)
    assert np.median(near[near < 0.15]) == pytest.approx(0.108, abs=0.02)


def test_follows_the_pose_and_front_facing():
    joints = t_pose_joints(1.75) + [0.5, 0.0, 2.0]  # moved: the samples move too
    pts = sample_humanoid(joints, 500, rng=3)
    assert np.mean(pts, axis=0)[2] == pytest.approx(2.0, abs=0.05)
    front = sample_humanoid(joints, 500, rng=3, front_facing=True, view_direction=(0, 0, 1))
    # a camera looking along +Z sees the side facing -Z: the near half of the body
    assert np.mean(front[:, 2]) < np.mean(pts[:, 2]) - 0.03


def test_bad_input():
    with pytest.raises(ValueError, match=r"'joints'.*\(15, 3\)"):
        sample_humanoid(np.zeros((16, 3)), 10)
    with pytest.raises(ValueError, match="'joints'.*3 columns"):
        sample_humanoid(np.zeros((15, 2)), 10)
    bad = t_pose_joints()
    bad[0, 0] = np.nan
    with pytest.raises(ValueError, match="'joints'.*finite"):
        sample_humanoid(bad, 10)
    with pytest.raises(ValueError, match="'n_points'"):
        sample_humanoid(t_pose_joints(), 0)
    with pytest.raises(ValueError, match="'view_direction'"):
        sample_humanoid(t_pose_joints(), 10, view_direction=(0, 0, 0))
    with pytest.raises(ValueError, match="'rng'"):
        sample_humanoid(t_pose_joints(), 10, rng="seed")
