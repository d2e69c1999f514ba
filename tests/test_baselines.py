"""Baselines on perfect labels: a rendered sequence whose ground-truth label images
stand in for the forest, so that the tests measure the baselines' geometry alone."""

import hashlib

import numpy as np
import pytest

from posedrift.baselines import (
    ICPTracker,
    PDABaseline,
    ShottonBaseline,
    grid_edges,
    pda_skeleton,
    shotton_proposals,
)
from posedrift.evaluation import angle_errors, make_method
from posedrift.skeleton import JOINT_INDEX, joint_angles
from posedrift.skeleton._fit import prior_bone_lengths
from posedrift.tracking import FrameStatus


class OracleForest:
    """Test-only: turns the ground-truth label images into a forest's PartPrediction."""

    def __init__(self, frames, labels):
        self.table = {self._key(f.depth): lab for f, lab in zip(frames, labels, strict=True)}

    @staticmethod
    def _key(depth):
        return hashlib.sha1(np.ascontiguousarray(depth, np.float32).tobytes()).hexdigest()

    def predict(self, depth, mask, intrinsics):
        from posedrift.labelling._forest import PartPrediction

        truth = self.table[self._key(depth)].astype(np.int64) - 1
        valid = (depth > 0) & (truth >= 0) & (True if mask is None else mask)
        rows, cols = np.nonzero(valid)
        prob = np.zeros((len(rows), 15), np.float32)
        prob[np.arange(len(rows)), truth[rows, cols]] = 1.0
        labels = np.full(depth.shape, -1, np.int16)
        labels[rows, cols] = truth[rows, cols]
        return PartPrediction(
            labels=labels, pixels=np.column_stack([rows, cols]).astype(np.intp), probabilities=prob
        )


@pytest.fixture(scope="module")
def clip(mocap_dir):
    from posedrift.synthetic import build_sequence
    from posedrift.synthetic._motion import bvh_motion

    seq = build_sequence(bvh_motion(mocap_dir / "cmu" / "001_01.bvh"), n_frames=60)
    return seq, OracleForest(seq.frames, seq.reference.labels)


RING = ("neck", "right_elbow", "left_elbow", "right_hand", "left_hand", "right_knee", "left_knee")


def test_shotton_on_the_calibration_frame(clip):
    seq, oracle = clip
    method = ShottonBaseline(seq.frames[0].intrinsics, forest=oracle)
    result = method.process(seq.frames[0])
    assert result.status == FrameStatus.REINITIALIZED and result.has_pose
    err = np.linalg.norm(result.joints - seq.reference.joints[0], axis=1)
    for name in RING:
        assert err[JOINT_INDEX[name]] < 0.05, name
    assert 1.6 < method.stature_ < 2.0  # CMU subject 1, about 1.85 m
    # hips and shoulders come from the shared skeleton fit (bone lengths along the part
    # axes), which is less exact than the ring joints: about 12 degrees at the hips here
    np.testing.assert_allclose(result.angles, seq.reference.angles[0], atol=14.0)


def test_pda_on_the_calibration_frame(clip):
    seq, oracle = clip
    method = PDABaseline(seq.frames[0].intrinsics, forest=oracle)
    result = method.process(seq.frames[0])
    assert result.has_pose
    # arms within a few degrees; the thighs' flesh (wide at the hip, narrow at the knee)
    # tilts their principal direction inwards from the bone by about 15 degrees
    np.testing.assert_allclose(result.angles[:4], seq.reference.angles[0, :4], atol=4.0)
    np.testing.assert_allclose(result.angles[4:], seq.reference.angles[0, 4:], atol=17.0)
    assert np.linalg.norm(result.joints[JOINT_INDEX["neck"]] - seq.reference.joints[0, 1]) < 0.05


@pytest.mark.parametrize("cls", [ShottonBaseline, PDABaseline])
def test_baselines_over_a_clip_with_perfect_labels(clip, cls):
    seq, oracle = clip
    method = cls(seq.frames[0].intrinsics, forest=oracle)
    results = [method.process(f) for f in seq.frames]
    joints = np.stack([r.joints for r in results])
    errors = angle_errors(joint_angles(joints), seq.reference.angles)
    assert errors["mean"] < 12.0
    assert all(r.has_pose for r in results)
    # reset forgets the calibration; labels returned are the oracle's
    method.reset(seq.frames[0].intrinsics)
    assert method.stature_ is None
    assert len(results[5].points) == len(results[5].labels) > 100


def test_no_person_is_reported_not_raised(clip):
    seq, oracle = clip
    from posedrift.camera import DepthFrame

    empty = DepthFrame(np.zeros(seq.frames[0].intrinsics.shape), seq.frames[0].intrinsics)
    for cls in (ShottonBaseline, PDABaseline):
        result = cls(empty.intrinsics, forest=oracle).process(empty)
        assert result.status == FrameStatus.NO_PERSON and not result.has_pose


def test_shotton_proposals_weighting_and_push_back():
    rng = np.random.default_rng(0)
    near = rng.normal([0.0, 0.0, 2.0], 0.01, (200, 3))
    far = rng.normal([0.3, 0.0, 2.0], 0.01, (50, 3))
    pts = np.concatenate([near, far])
    prob = np.zeros((250, 2))
    prob[:, 0] = 1.0
    prob[200:, 0] = 0.1  # below the threshold: no votes
    prob[200:, 1] = 0.9
    pushed, surface = shotton_proposals(pts, prob, threshold=0.14, push_back=0.04)
    np.testing.assert_allclose(surface[0], near.mean(axis=0), atol=0.005)
    np.testing.assert_allclose(surface[1], far.mean(axis=0), atol=0.005)
    np.testing.assert_allclose(np.linalg.norm(pushed - surface, axis=1), 0.04, atol=1e-9)
    assert np.all(pushed[:, 2] > surface[:, 2])


def test_pda_angles_are_the_direction_angles():
    # a constructed body: trunk along +Y (down in the camera frame), a right arm of two
    # straight segments bent at 90 degrees, everything else missing
    rng = np.random.default_rng(1)

    def segment(a, b, n=80):
        t = rng.uniform(0, 1, (n, 1))
        return a + t * (np.asarray(b) - a) + rng.normal(0, 0.004, (n, 3))

    z = 3.0
    upper = segment([0, -0.3, z], [0, -0.05, z])
    lower = segment([0, 0.0, z], [0, 0.25, z])
    r_upper = segment([-0.25, -0.25, z], [-0.25, 0.05, z])  # hanging down
    r_fore = segment([-0.25, 0.08, z], [-0.25 - 0.001, 0.1, z - 0.25])  # towards the camera
    pts = np.concatenate([upper, lower, r_upper, r_fore])
    labels = np.repeat([1, 2, 3, 5], 80)
    joints, conf, dirs = pda_skeleton(pts, labels, bone_lengths=prior_bone_lengths(1.75))
    angles = dict(zip(("le", "re", "ls", "rs"), joint_angles(joints)[:4], strict=True))
    assert angles["rs"] == pytest.approx(0.0, abs=3.0)  # the arm hangs along the trunk
    assert angles["re"] == pytest.approx(180 - 85.4, abs=4.0)  # forearm bent forward
    assert conf[JOINT_INDEX["right_hand"]] == 1.0 and conf[JOINT_INDEX["left_hand"]] < 1.0
    assert set(dirs) >= {"trunk", "right_upper_arm", "right_forearm"}
    # no torso: no pose
    none, _, _ = pda_skeleton(r_upper, np.full(80, 3), bone_lengths=prior_bone_lengths(1.75))
    assert np.isnan(none).all()


def test_grid_edges_respect_depth_steps():
    depth = np.array([[1.0, 1.01, 1.5]], np.float32)
    pixels = np.array([[0, 0], [0, 1], [0, 2]])
    rows, cols = grid_edges(pixels, depth, max_step=0.05)
    assert rows.tolist() == [0] and cols.tolist() == [1]


def test_icp_wraps_the_tracker():
    from posedrift.camera import camera_preset

    method = ICPTracker(camera_preset("kinect1-qvga"), forest=object())
    assert method.name == "icp" and method.tracker.correspondence == "icp"
    assert make_method("pda", camera_preset("kinect1-qvga"), forest=object()).name == "pda"


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [({"bandwidth": 0.0}, "bandwidth"), ({"threshold": 1.5}, "threshold")],
)
def test_shotton_rejects_bad_parameters(kwargs, match):
    from posedrift.camera import camera_preset

    with pytest.raises(ValueError, match=match):
        ShottonBaseline(camera_preset("kinect1-qvga"), forest=object(), **kwargs)
