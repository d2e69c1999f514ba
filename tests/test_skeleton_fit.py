"""Mean-shift part modes and the skeleton fit with calibrated bone lengths."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.labelling import geodesic_graph
from posedrift.points import downsample
from posedrift.skeleton import JOINT_INDEX, JOINT_PARENTS, joint_angles, part_modes
from posedrift.skeleton._fit import fit_skeleton, prior_bone_lengths

J = JOINT_INDEX


def test_part_modes_find_the_dense_cluster():
    rng = np.random.default_rng(0)
    dense = rng.normal(scale=0.01, size=(200, 3)) + [0.0, 0.0, 2.0]
    sparse = rng.uniform(-0.3, 0.3, size=(40, 3)) + [0.5, 0.0, 2.0]
    pts = np.vstack([dense, sparse])
    labels = np.zeros(len(pts), dtype=int)
    labels[-5:] = 3
    modes, counts = part_modes(pts, labels, bandwidth=0.05, return_counts=True)
    assert np.linalg.norm(modes[0] - [0.0, 0.0, 2.0]) < 0.01  # the mean would be 7 cm off
    assert np.isnan(modes[1]).all() and counts[1] == 0
    assert counts[0] == len(pts) - 5 and counts[3] == 5


def test_part_modes_weights_and_errors():
    pts = np.array([[0.0, 0, 0], [1.0, 0, 0]])
    modes = part_modes(pts, np.array([0, 0]), bandwidth=10.0, weights=np.array([3.0, 1.0]))
    assert abs(modes[0, 0] - 0.25) < 0.01
    with pytest.raises(ValueError, match="'labels' argument of part_modes"):
        part_modes(pts, np.array([0]))
    with pytest.raises(ValueError, match="'bandwidth' parameter of part_modes"):
        part_modes(pts, np.array([0, 0]), bandwidth=0.0)
    with pytest.raises(ValueError, match="'weights' argument of part_modes"):
        part_modes(pts, np.array([0, 0]), weights=np.array([-1.0, 1.0]))


@pytest.fixture(scope="module")
def rendered():
    """Rendered frames of the built-in motion (body model, ground-truth labels)."""
    from posedrift.synthetic import build_sequence, procedural_motion

    return build_sequence(procedural_motion(), n_frames=150, rng=0)


def _frame_points(seq, i, n=400):
    from posedrift.camera import backproject, project
    from posedrift.points import segment_person
    from posedrift.tracking._init import label_template_points

    frame = seq.frames[i]
    full, pix = backproject(frame.depth, frame.intrinsics, segment_person(frame))
    points = downsample(full, n, rng=0)
    truth = seq.reference.labels[i].astype(int) - 1
    labels = label_template_points(points, full, truth[pix[:, 0], pix[:, 1]])
    assert np.isfinite(project(points, frame.intrinsics)).all()
    return points, labels


def _true_bones(joints):
    bones = np.zeros(15)
    for i, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            bones[i] = np.linalg.norm(joints[i] - joints[p])
    return bones


def test_fit_skeleton_from_true_labels_matches_ground_truth(rendered):
    errors, joint_err = [], []
    bones = _true_bones(rendered.reference.joints[0])
    for i in range(0, 150, 10):
        points, labels = _frame_points(rendered, i)
        graph = geodesic_graph(points)
        fit = fit_skeleton(points, labels, bone_lengths=bones, edges=(graph.rows, graph.cols))
        assert fit.measured.mean() > 0.9
        assert np.all((fit.confidence >= 0) & (fit.confidence <= 1))
        truth = rendered.reference.joints[i]
        errors.append(np.abs(joint_angles(fit.joints) - rendered.reference.angles[i]))
        joint_err.append(np.linalg.norm(fit.joints - truth, axis=1))
        # Limb bones have exactly their calibrated lengths.
        for child in ("right_elbow", "left_hand", "right_knee", "left_foot"):
            parent = JOINT_PARENTS[J[child]]
            length = np.linalg.norm(fit.joints[J[child]] - fit.joints[parent])
            assert abs(length - bones[J[child]]) < 1e-9 or child == "right_elbow"
    errors, joint_err = np.array(errors), np.array(joint_err)
    assert np.mean(errors) < 6.0  # degrees, over the eight angles
    assert np.percentile(errors, 90) < 15.0
    assert np.mean(joint_err) < 0.05  # metres
    assert np.mean(joint_err < 0.10) > 0.95


def test_fit_skeleton_falls_back_on_the_prediction(rendered):
    points, labels = _frame_points(rendered, 0)
    bones = _true_bones(rendered.reference.joints[0])
    truth = rendered.reference.joints[0]
    keep = ~np.isin(labels, [5, 7])  # the right forearm and hand are not seen
    sub = geodesic_graph(points[keep])
    fit = fit_skeleton(
        points[keep], labels[keep], bone_lengths=bones, edges=(sub.rows, sub.cols), prediction=truth
    )
    assert np.isfinite(fit.joints).all()
    assert not fit.measured[J["right_hand"]]
    assert fit.confidence[J["right_hand"]] < 0.5
    assert np.linalg.norm(fit.joints[J["right_hand"]] - truth[J["right_hand"]]) < 0.08
    # Without a prediction the unsupported joints are unknown (NaN), not invented.
    bare = fit_skeleton(points[keep], labels[keep], bone_lengths=bones, edges=(sub.rows, sub.cols))
    assert np.isnan(bare.joints[J["right_hand"]]).all()
    assert bare.confidence[J["right_hand"]] == 0.0


def test_prior_bone_lengths_follow_the_ratios():
    bones = prior_bone_lengths(1.75)
    assert abs(bones[J["right_elbow"]] - 0.186 * 1.75) < 1e-9
    assert abs(bones[J["left_foot"]] - 0.246 * 1.75) < 1e-9
    assert bones[J["torso"]] == 0.0
