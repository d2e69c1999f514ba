"""Algorithm 2 (labelling template set): geodesic graph, distances and relabelling."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.labelling import geodesic_distances, geodesic_graph, relabel
from posedrift.points import sample_humanoid
from posedrift.skeleton import JOINT_INDEX, PART_JOINTS, t_pose_joints
from posedrift.skeleton._fit import bone_anchors, prior_bone_lengths
from posedrift.tracking._init import measure_reach


def nearest_bone_labels(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Ground-truth parts of capsule-body points: the nearest bone (PART_JOINTS)."""
    named = {n: joints[i] for n, i in JOINT_INDEX.items()}
    named["pelvis"] = 0.5 * (named["right_hip"] + named["left_hip"])
    for side in ("right", "left"):
        fore = named[f"{side}_hand"] - named[f"{side}_elbow"]
        named[f"{side}_hand_tip"] = named[f"{side}_hand"] + 0.7 * fore
        named[f"{side}_toe"] = named[f"{side}_foot"] + np.array([0.0, -0.05, 0.2])
    a = np.array([named[p] for p, _ in PART_JOINTS])
    b = np.array([named[q] for _, q in PART_JOINTS])
    ab = b - a
    t = np.einsum("pkj,kj->pk", points[:, None] - a[None], ab) / np.einsum("kj,kj->k", ab, ab)
    closest = a[None] + np.clip(t, 0, 1)[..., None] * ab[None]
    d = np.linalg.norm(points[:, None] - closest, axis=2)
    radii = np.array([0.11, 0.17, 0.17, 0.06, 0.06, 0.05, 0.05, 0.04, 0.04, 0.1, 0.1] + [0.07] * 4)
    return np.argmin(d - radii, axis=1)


@pytest.fixture(scope="module")
def body():
    joints = t_pose_joints(1.75)
    from posedrift.points import downsample

    points = downsample(sample_humanoid(joints, 6000, rng=0, front_facing=True), 500)
    return joints, points, nearest_bone_labels(points, joints)


def test_graph_geodesics_on_a_plane_match_euclidean():
    x, y = np.meshgrid(np.arange(20) * 0.03, np.arange(20) * 0.03)
    pts = np.column_stack([x.ravel(), y.ravel(), np.full(400, 2.0)])
    pts += np.random.default_rng(0).normal(scale=0.003, size=pts.shape)
    graph = geodesic_graph(pts)
    geo = geodesic_distances(graph, pts, pts[[0]])[0]
    euc = np.linalg.norm(pts - pts[0], axis=1)
    ratio = geo[1:] / euc[1:]
    assert np.median(ratio) < 1.1  # a k-NN path is only slightly longer than the chord
    assert ratio.min() >= 1.0 - 1e-9


def test_graph_does_not_bridge_a_gap_or_a_depth_step():
    # Two parallel strips 10 cm apart (an arm beside the torso) are not connected.
    s = np.arange(30) * 0.02
    a = np.column_stack([s, np.zeros(30), np.full(30, 2.0)])
    b = np.column_stack([s, np.full(30, 0.1), np.full(30, 2.0)])
    graph = geodesic_graph(np.vstack([a, b]), k=6)
    geo = geodesic_distances(graph, np.vstack([a, b]), a[[0]])[0]
    assert np.isinf(geo[30:]).all()
    # A strip 8 cm in front of a plane, overlapping it in the image: cut by depth.
    c = np.column_stack([s, np.full(30, 0.02), np.full(30, 1.92)])
    both = np.vstack([a, c])
    geo = geodesic_distances(geodesic_graph(both, max_edge=0.1), both, a[[0]])[0]
    assert np.isinf(geo[30:]).all()


def test_relabel_identity_on_correct_labels(body):
    joints, points, labels = body
    bones = prior_bone_lengths(1.75)
    anchors = bone_anchors(joints, bones)
    graph = geodesic_graph(points)
    reach = measure_reach(graph, points, labels, anchors, height=1.75)
    out = relabel(points, labels, anchors, height=1.75, ratios=reach, graph=graph)
    assert np.mean(out == labels) > 0.99


def test_relabel_fixes_stray_labels(body):
    joints, points, labels = body
    bones = prior_bone_lengths(1.75)
    anchors = bone_anchors(joints, bones)
    graph = geodesic_graph(points)
    reach = measure_reach(graph, points, labels, anchors, height=1.75)
    rng = np.random.default_rng(1)
    noisy = labels.copy()
    # Hands and head points labelled as feet and vice versa: geodesically impossible.
    stray = rng.choice(len(points), 40, replace=False)
    noisy[stray] = (labels[stray] + 7) % 15
    wrong_before = np.sum(noisy != labels)
    out = relabel(points, noisy, anchors, height=1.75, ratios=reach, graph=graph)
    far = np.array(
        [
            np.linalg.norm(anchors[labels[i]].mean(0) - anchors[noisy[i]].mean(0)) > 0.5
            for i in stray
        ]
    )
    assert np.mean(out[stray[far]] == labels[stray[far]]) > 0.9
    assert np.sum(out != labels) < 0.3 * wrong_before


def test_relabel_paper_rule_without_evidence():
    line = np.column_stack([np.linspace(0, 1, 41), np.zeros(41), np.zeros(41)])
    labels = np.zeros(41, dtype=int)
    joints = np.full((15, 3), np.nan)
    joints[0], joints[1] = (0, 0, 0), (1, 0, 0)
    ratios = np.zeros(15)
    ratios[:2] = 0.5
    uniform = np.ones((41, 15))
    out = relabel(
        line, labels, joints, height=1.0, ratios=ratios, evidence=uniform, keep_plausible=False
    )
    assert (out[:20] == 0).all() and (out[21:] == 1).all()


def test_relabel_errors():
    pts = np.zeros((4, 3))
    with pytest.raises(ValueError, match="'labels' argument of relabel"):
        relabel(pts, np.zeros(3), np.zeros((15, 3)), height=1.7, ratios=np.ones(15))
    with pytest.raises(ValueError, match="must agree"):
        relabel(pts, np.zeros(4), np.zeros((15, 3)), height=1.7, ratios=np.ones(14))
    with pytest.raises(ValueError, match="'height' parameter of relabel"):
        relabel(pts, np.zeros(4), np.zeros((15, 3)), height=-1.0, ratios=np.ones(15))
    with pytest.raises(ValueError, match="'evidence' argument of relabel"):
        relabel(
            pts + np.arange(4)[:, None],
            np.zeros(4),
            np.zeros((15, 3)),
            height=1.7,
            ratios=np.ones(15),
            evidence=np.ones((4, 3)),
        )
