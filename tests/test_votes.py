"""Joint votes at the forest's leaves: casting, mean shift, learning, the model file,
the skeleton refinement and the tracker's use of them."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.camera import backproject
from posedrift.labelling import BodyPartForest, JointVotes, fit_joint_votes, joint_modes
from posedrift.skeleton import JOINT_INDEX, refine_with_votes, t_pose_joints

J = JOINT_INDEX


def _votes(n_leaves: int = 3) -> JointVotes:
    """Leaf 0 votes for the neck 10 cm behind; leaf 1 for a hand; leaf 2 for nothing."""
    joint = np.full((n_leaves, 2), -1, np.int8)
    offset = np.zeros((n_leaves, 2, 3), np.float32)
    weight = np.zeros((n_leaves, 2), np.float32)
    joint[0, 0], offset[0, 0], weight[0, 0] = J["neck"], (0.0, 0.0, 0.1), 0.8
    joint[1, 1], offset[1, 1], weight[1, 1] = J["left_hand"], (0.05, 0.0, 0.0), 0.4
    return JointVotes(joint=joint, offset=offset, weight=weight, radius=0.2)


@pytest.mark.parametrize("compiled", [True, False])
def test_cast_puts_each_vote_at_its_point_plus_the_leaf_offset(compiled):
    votes = _votes()
    points = np.array([[0.0, 0.0, 2.0], [1.0, 0.0, 2.0], [2.0, 0.0, 2.0]])
    # Two trees; point 2 reached nothing in tree 1 (-1) and a vote-less leaf in tree 0.
    leaves = np.array([[0, 1, 2], [0, 0, -1]])
    where, joint, weight = votes.cast(points, leaves, compiled=compiled)
    order = np.lexsort((where[:, 0], joint))
    where, joint, weight = where[order], joint[order], weight[order]
    np.testing.assert_allclose(
        where, [[0, 0, 2.1], [0, 0, 2.1], [1, 0, 2.1], [1.05, 0, 2]], atol=1e-6
    )
    assert joint.tolist() == [J["neck"]] * 3 + [J["left_hand"]]
    np.testing.assert_allclose(weight, [0.4, 0.4, 0.4, 0.2])  # shares over two trees


def test_compiled_cast_gives_the_numpy_votes_exactly():
    from posedrift.labelling import _votes as votes_module

    if votes_module._ckernels is None:
        pytest.skip("the compiled kernels (posedrift.labelling._ckernels) are not built")
    rng = np.random.default_rng(3)
    n_leaves, per_leaf = 300, 4
    joint = rng.integers(-1, 15, size=(n_leaves, per_leaf)).astype(np.int8)
    weight = np.where(joint >= 0, rng.random((n_leaves, per_leaf)), 0.0).astype(np.float32)
    weight[::7] = 0.0  # leaves without votes
    offset = rng.uniform(-0.2, 0.2, size=(n_leaves, per_leaf, 3)).astype(np.float32)
    votes = JointVotes(joint=joint, offset=offset, weight=weight, radius=0.2)
    points = rng.normal([0, 0, 2.5], 0.4, size=(500, 3))
    leaves = rng.integers(-1, n_leaves, size=(3, 500))
    for joints in (None, [1, 2, 5, 6]):
        fast = votes.cast(points, leaves, joints=joints)
        slow = votes.cast(points, leaves, joints=joints, compiled=False)
        assert len(fast[0]) > 1000
        for a, b in zip(fast, slow, strict=True):
            np.testing.assert_array_equal(a, b)
            assert a.dtype == b.dtype
    # Leaves without any vote slot (K = 0): no votes either way.
    empty = JointVotes(joint=joint[:, :0], offset=offset[:, :0], weight=weight[:, :0], radius=0.2)
    assert all(len(a) == 0 for a in empty.cast(points, leaves))
    with pytest.raises(ValueError, match="'leaves' argument of JointVotes.cast"):
        votes.cast(points, leaves[:, :-1])
    with pytest.raises(ValueError, match="'leaves' argument of JointVotes.cast"):
        votes.cast(points, leaves + n_leaves)
    with pytest.raises(ValueError, match=r"points \(N, 3\) and leaves \(T, N\)"):
        votes.cast(points[:, :2], leaves)


def test_joint_votes_reject_malformed_arrays():
    good = _votes()
    with pytest.raises(ValueError, match="joint.*offset.*weight"):
        JointVotes(joint=good.joint, offset=good.offset[:, :1], weight=good.weight, radius=0.2)
    with pytest.raises(ValueError, match="joint indices"):
        JointVotes(joint=good.joint + 20, offset=good.offset, weight=good.weight, radius=0.2)
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        JointVotes(joint=good.joint, offset=good.offset, weight=good.weight + 2, radius=0.2)
    with pytest.raises(ValueError, match="finite"):
        JointVotes(joint=good.joint, offset=good.offset * np.nan, weight=good.weight, radius=0.2)
    with pytest.raises(ValueError, match="'radius'"):
        JointVotes(joint=good.joint, offset=good.offset, weight=good.weight, radius=-1.0)
    with pytest.raises(ValueError, match="within the radius"):
        JointVotes(joint=good.joint, offset=good.offset, weight=good.weight, radius=0.05)


def test_joint_modes_climb_to_the_cluster_by_the_seed(meanshift_kernel):
    rng = np.random.default_rng(0)
    centre = np.array([0.1, -0.3, 2.5])
    other = centre + [0.4, 0.0, 0.0]  # a second, heavier cluster far from the seed
    where = np.vstack(
        [centre + 0.01 * rng.normal(size=(200, 3)), other + 0.01 * rng.normal(size=(400, 3))]
    )
    joint = np.full(len(where), J["right_elbow"])
    weight = np.ones(len(where))
    seeds = np.full((15, 3), np.nan)
    seeds[J["right_elbow"]] = centre + [0.03, 0.02, 0.0]
    modes = joint_modes(where, joint, weight, seeds)
    assert np.linalg.norm(modes[J["right_elbow"]] - centre) < 0.003  # 3 mm
    # Identity: votes exactly at the seed stay there.
    at = joint_modes(np.tile(centre, (5, 1)), np.full(5, J["neck"]), np.ones(5), seeds * 0 + centre)
    np.testing.assert_allclose(at[J["neck"]], centre, atol=1e-12)
    # Unseeded: from the weighted mean; too little weight or no votes: NaN.
    unseeded = joint_modes(where, joint, weight, np.full((15, 3), np.nan))
    assert np.isfinite(unseeded[J["right_elbow"]]).all()
    light = joint_modes(where[:3], joint[:3], np.full(3, 0.1), seeds)
    assert np.isnan(light).all()
    only = joint_modes(where, joint, weight, seeds, joints=[J["neck"]])
    assert np.isnan(only).all()  # the elbow's votes were not asked for
    far = seeds.copy()
    far[J["right_elbow"]] = centre + [5.0, 0.0, 0.0]  # beyond every vote's kernel
    assert np.isnan(joint_modes(where, joint, weight, far)[J["right_elbow"]]).all()


def test_refine_with_votes_identity_weights_and_bone_lengths():
    pose = t_pose_joints(1.75)
    np.testing.assert_allclose(refine_with_votes(pose, pose), pose, atol=1e-12)
    voted = pose + [0.0, 0.0, 0.1]  # every vote 10 cm behind
    voted[J["left_elbow"]] += [0.0, -0.2, 0.0]  # the left upper arm voted lower
    np.testing.assert_allclose(
        refine_with_votes(pose, voted, trunk_weight=0.0, arm_weight=0.0), pose, atol=1e-12
    )
    out = refine_with_votes(pose, voted, trunk_weight=0.5, arm_weight=0.4)
    for name in ("head", "neck", "right_shoulder", "left_shoulder"):
        np.testing.assert_allclose(out[J[name]] - pose[J[name]], [0, 0, 0.05], atol=1e-12)
    head_bone = out[J["head"]] - out[J["neck"]]
    assert abs(np.linalg.norm(head_bone) - np.linalg.norm(pose[J["head"]] - pose[J["neck"]])) < 1e-9
    for name in ("right_hip", "left_hip", "right_knee", "left_foot"):  # legs untouched
        np.testing.assert_array_equal(out[J[name]], pose[J[name]])
    pelvis = 0.5 * (out[J["right_hip"]] + out[J["left_hip"]])
    np.testing.assert_allclose(out[J["torso"]], 0.5 * (out[J["neck"]] + pelvis))
    for side in ("right", "left"):
        s, e, h = (J[f"{side}_{n}"] for n in ("shoulder", "elbow", "hand"))
        for a, b in ((s, e), (e, h)):  # bone lengths kept to the micrometre
            assert abs(np.linalg.norm(out[b] - out[a]) - np.linalg.norm(pose[b] - pose[a])) < 1e-6
        forearm = (out[h] - out[e]) / np.linalg.norm(out[h] - out[e])
        np.testing.assert_allclose(forearm, (pose[h] - pose[e]) / np.linalg.norm(pose[h] - pose[e]))
    # The right arm's vote is parallel to it: no turn. The left one turns down.
    right_dir = out[J["right_elbow"]] - out[J["right_shoulder"]]
    np.testing.assert_allclose(
        right_dir / np.linalg.norm(right_dir),
        (pose[J["right_elbow"]] - pose[J["right_shoulder"]])
        / np.linalg.norm(pose[J["right_elbow"]] - pose[J["right_shoulder"]]),
        atol=1e-12,
    )
    assert out[J["left_elbow"]][1] < pose[J["left_elbow"]][1] - 0.03
    # No votes at all (NaN): nothing moves.
    np.testing.assert_array_equal(refine_with_votes(pose, np.full((15, 3), np.nan)), pose)


@pytest.fixture(scope="module")
def rendered():
    """A small forest on rendered bodies, and fresh frames with their true joints."""
    pytest.importorskip("sklearn")
    from posedrift.labelling._train import SceneRanges, synthetic_training_frames, train_forest
    from posedrift.synthetic import procedural_motion

    motion = procedural_motion(seconds=4.0)
    ranges = SceneRanges(wide_fraction=0.0, noise_fraction=0.0)

    def frames(n, seed):
        return synthetic_training_frames(n, [motion], ranges=ranges, rng=seed)

    forest = train_forest(
        frames(40, 0),
        n_frames=40,
        n_offsets=150,
        pixels_per_frame=500,
        max_depth=12,
        n_jobs=1,
        rng=1,
    )
    votes = fit_joint_votes(forest, frames(60, 2), n_frames=60, rng=3)
    return forest.with_votes(votes), list(frames(6, 4))


def test_learned_votes_find_the_true_joints(rendered):
    """Each rendered frame's trunk and arm joints from the votes alone (mean shift
    seeded 5 cm off the truth) fall within a few centimetres of the true ones."""
    forest, frames = rendered
    rng = np.random.default_rng(5)
    errors = []
    for frame in frames:
        points, pixels = backproject(frame.depth, frame.intrinsics, frame.mask)
        _, leaves = forest.predict_pixels(
            frame.depth, pixels, frame.intrinsics, mask=frame.mask, return_leaves=True
        )
        seeds = frame.joints + rng.normal(scale=0.05 / np.sqrt(3), size=(15, 3))
        modes = joint_modes(*forest.votes.cast(points, leaves), seeds)
        errors.append(np.linalg.norm(modes - frame.joints, axis=1))
    median = np.nanmedian(errors, axis=0)
    for name in ("neck", "right_shoulder", "left_shoulder", "right_hip", "left_hip"):
        assert median[J[name]] < 0.05, (name, median[J[name]])
    # Better than the seeds they started from.
    assert np.nanmedian(errors) < 0.035


def test_fit_joint_votes_needs_joints_and_pixels(rendered):
    forest, frames = rendered
    from dataclasses import replace

    with pytest.raises(ValueError, match="frame 0 has none"):
        fit_joint_votes(forest, [replace(frames[0], joints=None)], n_frames=1)
    empty = replace(frames[0], labels=np.zeros_like(frames[0].labels))
    with pytest.raises(ValueError, match="no foreground pixel"):
        fit_joint_votes(forest, [empty], n_frames=1)


def test_votes_survive_the_model_file(rendered, tmp_path):
    forest, _ = rendered
    loaded = BodyPartForest.load(forest.save(tmp_path / "voted.npz"))
    np.testing.assert_array_equal(loaded.votes.joint, forest.votes.joint)
    # Stored in int8 steps of radius / 127 and uint8 steps of 1/255.
    step = forest.votes.radius / 127
    assert np.abs(loaded.votes.offset - forest.votes.offset).max() <= 0.5 * step + 1e-6
    assert np.abs(loaded.votes.weight - forest.votes.weight).max() <= 0.5 / 255 + 1e-6
    bare = BodyPartForest.load(forest.with_votes(None).save(tmp_path / "bare.npz"))
    assert bare.votes is None
    with np.load(tmp_path / "voted.npz", allow_pickle=False) as npz:
        arrays = {k: npz[k] for k in npz.files}
    partial = {k: v for k, v in arrays.items() if k != "vote_weight"}
    np.savez(tmp_path / "partial.npz", **partial)
    with pytest.raises(ValueError, match="incomplete joint votes"):
        BodyPartForest.load(tmp_path / "partial.npz")
    np.savez(tmp_path / "typed.npz", **{**arrays, "vote_offset": arrays["vote_offset"] * 1.0})
    with pytest.raises(ValueError, match="unexpected dtypes"):
        BodyPartForest.load(tmp_path / "typed.npz")
    with pytest.raises(ValueError, match="one row per leaf"):
        forest.with_votes(_votes(5))


def test_predict_pixels_returns_the_leaves_behind_its_probabilities(rendered):
    forest, frames = rendered
    frame = frames[0]
    _, pixels = backproject(frame.depth, frame.intrinsics, frame.mask)
    pixels = np.vstack([pixels[::20], [[0, 0]]])  # the last one off the person
    probs, leaves = forest.predict_pixels(
        frame.depth, pixels, frame.intrinsics, mask=frame.mask, return_leaves=True
    )
    assert leaves.shape == (forest.n_trees, len(pixels)) and (leaves[:, -1] == -1).all()
    np.testing.assert_allclose(
        forest.leaf_values[leaves[:, :-1]].mean(axis=0), probs[:-1], atol=1e-6
    )


def test_the_tracker_places_the_shoulders_better_with_votes():
    """On the built-in motion the default model's votes bring the tracker's shoulders
    and neck closer to the truth; with vote weights 0 they are not used."""
    from posedrift.synthetic import build_sequence, procedural_motion
    from posedrift.tracking import PoseTracker

    assert BodyPartForest.load_default().votes is not None
    seq = build_sequence(procedural_motion(), n_frames=60, rng=0)
    trunk = [J[n] for n in ("neck", "right_shoulder", "left_shoulder")]
    error = {}
    for weights in ((0.5, 0.4), (0.0, 0.0)):
        tracker = PoseTracker(seq.frames[0].intrinsics, vote_weights=weights)
        joints = np.stack([tracker.process(f).joints for f in seq.frames])
        error[weights] = np.linalg.norm(joints - seq.reference.joints, axis=2)[:, trunk].mean()
    assert error[(0.5, 0.4)] < error[(0.0, 0.0)] - 0.003, error
    with pytest.raises(ValueError, match="'vote_weights'"):
        PoseTracker(seq.frames[0].intrinsics, vote_weights=(0.5,))
    with pytest.raises(ValueError, match="vote_weights"):
        PoseTracker(seq.frames[0].intrinsics, vote_weights=(0.5, 2.0))
