"""Algorithm 2 (labelling template set): geodesic graph, distances and relabelling."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.labelling import geodesic_distances, geodesic_graph, merge_islands, relabel
from posedrift.points import sample_humanoid
from posedrift.skeleton import JOINT_INDEX, PART_INDEX, PART_JOINTS, t_pose_joints
from posedrift.skeleton._fit import bone_anchors, part_boundaries, prior_bone_lengths
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


UPPER_ARMS = (PART_INDEX["right_upper_arm"], PART_INDEX["left_upper_arm"])


def test_merge_islands_identity_on_whole_parts(body):
    _, points, labels = body
    graph = geodesic_graph(points)
    assert merge_islands(labels, graph, UPPER_ARMS) is labels
    assert merge_islands(labels, graph, range(15)) is labels  # every part in one piece


def test_merge_islands_gives_a_forearm_its_points_back_and_the_elbow_its_place(body):
    # A few forearm points near the wrist labelled upper arm (a forearm pointed at the
    # camera, its elbow hidden) make an upper-arm/forearm boundary far from the elbow.
    joints, points, labels = body
    graph = geodesic_graph(points)
    ua, fa = PART_INDEX["left_upper_arm"], PART_INDEX["left_forearm"]
    forearm = np.flatnonzero(labels == fa)
    wrist = joints[JOINT_INDEX["left_hand"]]
    stray = forearm[np.argsort(np.linalg.norm(points[forearm] - wrist, axis=1))[:4]]
    noisy = labels.copy()
    noisy[stray] = ua
    merged = merge_islands(noisy, graph, UPPER_ARMS)
    assert merged is not noisy and np.array_equal(merged, labels)
    assert merged.dtype == noisy.dtype

    def boundary(lab):  # the centre of the upper-arm/forearm boundary (the elbow's evidence)
        centres, _ = part_boundaries(points, lab, graph.rows, graph.cols)
        return centres[ua, fa]

    true = boundary(labels)
    assert np.linalg.norm(boundary(noisy) - true) > 0.05  # metres: pulled down the forearm
    assert np.linalg.norm(boundary(merged) - true) < 1e-9


def test_merge_islands_limits():
    # A row of 2 cm steps: label 1 at 0-9, then label 0, with pieces of label 1 of
    # 3 and 5 points and a lone point in between.
    points = np.column_stack([np.arange(40) * 0.02, np.zeros(40), np.full(40, 2.0)])
    graph = geodesic_graph(points, k=2)
    labels = np.zeros(40, dtype=np.int16)
    labels[:10] = 1
    labels[15:18] = 1  # 3 points: merged
    labels[25:30] = 1  # 5 points
    labels[35] = 1
    out = merge_islands(labels, graph, [1], max_points=4)
    assert out[15:18].tolist() == [0, 0, 0] and out[25:30].tolist() == [1] * 5
    assert out[35] == 0 and out[:10].tolist() == [1] * 10
    # No more than max_share of the part's points.
    out = merge_islands(labels, graph, [1], max_points=8, max_share=0.2)
    assert out[15:18].tolist() == [0, 0, 0] and out[25:30].tolist() == [1] * 5
    # A piece whose only neighbours are unlabelled keeps its label.
    unlabelled = labels.copy()
    unlabelled[14] = unlabelled[18] = -1
    out = merge_islands(unlabelled, graph, [1], max_points=4)
    assert out[15:18].tolist() == [1, 1, 1] and out[14] == -1
    # Parts with fewer than two points, and parts absent, change nothing.
    assert merge_islands(labels, graph, [7, 1], max_points=0) is labels


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


# --------------------------------------------------------------------------- speed rewrites
# The graph, the distances and the relabelling were rewritten for speed; these references
# are the straightforward versions they replaced, and the fast ones must agree bit for bit.


def _reference_graph(points, *, k=6, max_edge_factor=2.2, max_edge=None, depth_step=0.06):
    from scipy import sparse
    from scipy.spatial import cKDTree

    n = len(points)
    kk = min(k + 1, n)
    dist, idx = cKDTree(points).query(points, k=kk)
    dist, idx = dist[:, 1:], idx[:, 1:]
    spacing = float(np.median(dist[:, 0]))
    limit = max_edge if max_edge is not None else max_edge_factor * max(spacing, 1e-6)
    rows = np.repeat(np.arange(n), kk - 1)
    cols, lengths = idx.ravel(), dist.ravel()
    keep = (lengths <= limit) & (cols < n)
    if depth_step is not None:
        diff = points[np.minimum(cols, n - 1)] - points[rows]
        dz = np.abs(diff[:, 2])
        keep &= ~((dz > depth_step) & (dz > np.hypot(diff[:, 0], diff[:, 1])))
    rows, cols, lengths = rows[keep], cols[keep], lengths[keep]
    lo, hi = np.minimum(rows, cols), np.maximum(rows, cols)
    _, first = np.unique(lo * n + hi, return_index=True)
    lo, hi, lengths = lo[first], hi[first], np.maximum(lengths[first], 1e-9)
    matrix = sparse.coo_matrix(
        (np.concatenate([lengths, lengths]), (np.concatenate([lo, hi]), np.concatenate([hi, lo]))),
        shape=(n, n),
    ).tocsr()
    return lo, hi, lengths, spacing, matrix


def _reference_distances(graph, points, anchors, labels=None):
    """One undirected scipy Dijkstra per anchor, then the minimum per part."""
    from scipy.sparse.csgraph import dijkstra

    anchors = np.asarray(anchors, dtype=float)
    if anchors.ndim == 2:
        anchors = anchors[:, None, :]
    n_parts = anchors.shape[0]
    out = np.full((n_parts, len(points)), np.inf)
    for j in range(n_parts):
        for a in anchors[j]:
            if not np.isfinite(a).all():
                continue
            d2 = ((a[None, :] - points) ** 2).sum(-1)
            if labels is not None and (labels == j).any():
                d2 = np.where(labels == j, d2, np.inf)
            s = int(np.argmin(d2))
            geo = dijkstra(graph.matrix, directed=False, indices=s) + np.sqrt(d2[s])
            out[j] = np.minimum(out[j], geo)
    return out


def _reference_relabel(points, labels, anchors, *, height, ratios, alpha, evidence, graph, keep):
    geo = _reference_distances(graph, points, anchors, labels).T
    n_parts = len(ratios)
    with np.errstate(over="ignore", invalid="ignore"):
        z = np.clip(alpha * (geo - ratios[None, :] * height), -50.0, 50.0)
        z = np.where(np.isfinite(geo), z, 50.0)
        likelihood = 1.0 / (1.0 + np.exp(z))
    if evidence is None:
        evidence = np.zeros((len(points), n_parts))
        known = (labels >= 0) & (labels < n_parts)
        evidence[np.nonzero(known)[0], labels[known]] = 1.0
    known = (labels >= 0) & (labels < n_parts)
    fill = (evidence.sum(axis=1) <= 1e-6) & known
    evidence = evidence.copy()
    evidence[fill] = 0.0
    evidence[np.nonzero(fill)[0], labels[fill]] = 1.0
    total = evidence.sum(axis=1, keepdims=True)
    norm = np.where(total > 1e-6, evidence / np.where(total > 1e-6, total, 1.0), 1.0 / n_parts)
    score = (norm + 0.05) * likelihood
    new = np.argmax(score, axis=1) if not keep else np.argmax(norm, axis=1)
    if keep:
        rows = np.arange(len(new))
        bad = (likelihood[rows, new] < 0.5) & np.isfinite(geo[rows, new])
        new[bad] = np.argmax(score[bad], axis=1)
    stuck = score.max(axis=1) < 1e-6
    new[stuck] = np.where(labels[stuck] >= 0, labels[stuck], np.argmax(norm[stuck], axis=1))
    return new


def _clouds():
    """Point sets: a body, random blobs (several components), a tiny set, a depth step."""
    rng = np.random.default_rng(7)
    joints = t_pose_joints(1.7)
    from posedrift.points import downsample

    yield downsample(sample_humanoid(joints, 5000, rng=1, front_facing=True), 400)
    yield np.vstack([rng.normal(c, 0.05, size=(60, 3)) for c in ((0, 0, 2), (1, 0, 2), (0, 1, 3))])
    yield rng.uniform(size=(5, 3))
    s = np.arange(40) * 0.02
    yield np.vstack(
        [np.column_stack([s, np.zeros(40), np.full(40, 2.0)]), np.column_stack([s, s, 1.9 + s])]
    )


@pytest.mark.parametrize("options", [{}, {"k": 3, "max_edge": 0.05}, {"depth_step": None}])
def test_graph_equals_the_reference(options):
    for pts in _clouds():
        graph = geodesic_graph(pts, compiled=False, **options)
        lo, hi, lengths, spacing, matrix = _reference_graph(pts, **options)
        assert np.array_equal(graph.rows, lo) and np.array_equal(graph.cols, hi)
        assert np.array_equal(graph.lengths, lengths) and graph.spacing == spacing
        assert np.array_equal(graph.matrix.indptr, matrix.indptr)
        assert np.array_equal(graph.matrix.indices, matrix.indices)
        assert np.array_equal(graph.matrix.data, matrix.data)


def _same_graph(a, b):
    return (
        np.array_equal(a.rows, b.rows)
        and np.array_equal(a.cols, b.cols)
        and a.rows.dtype == b.rows.dtype == a.cols.dtype == b.cols.dtype == np.int64
        and np.array_equal(a.lengths, b.lengths)
        and a.spacing == b.spacing
        and np.array_equal(a.matrix.indptr, b.matrix.indptr)
        and np.array_equal(a.matrix.indices, b.matrix.indices)
        and np.array_equal(a.matrix.data, b.matrix.data)
    )


@pytest.mark.parametrize("options", [{}, {"k": 3, "max_edge": 0.05}, {"depth_step": None}])
def test_compiled_graph_matches_its_twin(options):
    """The compiled k-NN and CSR kernels give the twin's graph, bit for bit, wherever no
    two neighbours tie in distance (then either may be taken: the distances agree)."""
    from scipy.spatial import cKDTree

    from posedrift.labelling import _relabel

    if _relabel._ckernels is None:
        pytest.skip("the compiled kernels are not built (no C compiler at install)")
    rng = np.random.default_rng(11)
    clouds = list(_clouds())
    lattice = clouds.pop()  # equal spacings: ties everywhere
    clouds += [rng.normal(size=(n, 3)) * rng.uniform(0.01, 2.0, size=3) for n in (2, 3, 9, 700)]
    clouds.append(np.vstack([clouds[-1], clouds[-1][:50] + 1e-13]))  # near-duplicates
    clouds.append(np.full((4, 3), 2.0) + [[0, 0, 0], [0.1, 0, 0], [0, 0.2, 0], [0, 0, 0.4]])
    clouds.append(np.vstack([rng.normal(size=(300, 3)) * 1e-3, [[1e12, 0.0, 0.0]]]))  # far
    for pts in clouds:
        compiled = geodesic_graph(pts, **options)
        twin = geodesic_graph(pts, compiled=False, **options)
        assert _same_graph(compiled, twin)
    for pts in (lattice, np.round(rng.normal(size=(300, 3)) * 4) / 4):
        for k in (1, 6, 12):
            kk = min(k + 1, len(pts))
            dist, idx = _relabel._neighbours(pts, kk, compiled=True)
            ref = cKDTree(pts).query(pts, k=kk)[0].reshape(len(pts), kk)
            assert np.array_equal(dist, ref)
            own = np.linalg.norm(pts[idx] - pts[:, None], axis=2)
            assert np.allclose(own, dist, rtol=0, atol=1e-12)
        graph = geodesic_graph(pts, **options)
        assert np.array_equal(graph.matrix.toarray(), graph.matrix.toarray().T)
        assert (graph.rows < graph.cols).all()
    # More neighbours than points: missing ones are infinitely far, index n (as cKDTree).
    dist, idx = _relabel._neighbours(np.eye(3), 5, compiled=True)
    assert np.isinf(dist[:, 3:]).all() and (idx[:, 3:] == 3).all()


def test_duplicate_points_make_no_self_loops():
    pts = np.array([[0.0, 0, 2], [0.0, 0, 2], [0.02, 0, 2], [0.04, 0, 2]])
    for compiled in (True, False):
        graph = geodesic_graph(pts, k=3, compiled=compiled)
        assert (graph.rows != graph.cols).all() and graph.matrix.diagonal().sum() == 0
        assert graph.matrix[0, 1] == pytest.approx(1e-9)  # the duplicates stay joined


def _anchor_sets(pts, rng):
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    one = rng.uniform(lo, hi, size=(15, 3))
    many = rng.uniform(lo, hi, size=(15, 3, 3))
    many[4] = np.nan  # a part without anchors
    many[7, 1] = np.nan  # one anchor missing
    return one, many


@pytest.mark.parametrize("compiled", [True, False])
def test_distances_and_relabel_equal_the_reference(compiled, monkeypatch):
    from posedrift.labelling import _relabel

    if not compiled:
        monkeypatch.setattr(_relabel, "_ckernels", None)
    rng = np.random.default_rng(3)
    for pts in _clouds():
        graph = geodesic_graph(pts)
        labels = rng.integers(-1, 15, size=len(pts))
        for anchors in _anchor_sets(pts, rng):
            for lab in (None, labels):
                got = geodesic_distances(graph, pts, anchors, lab)
                ref = _reference_distances(graph, pts, anchors, lab)
                # One search from all of a part's anchors adds each gap first, the
                # reference last: the same path lengths up to rounding.
                assert np.array_equal(np.isinf(got), np.isinf(ref))
                np.testing.assert_allclose(got, ref, rtol=1e-13, atol=0)
            ratios = rng.uniform(0.05, 0.4, size=15)
            evidence = rng.random((len(pts), 15)) ** 4
            evidence[: len(pts) // 10] = 0.0  # rows without evidence
            for alpha in (5.0, 60.0, 400.0):
                for keep in (True, False):
                    for ev in (None, evidence):
                        kw = dict(height=1.7, ratios=ratios, alpha=alpha, graph=graph)
                        got = relabel(pts, labels, anchors, evidence=ev, keep_plausible=keep, **kw)
                        ref = _reference_relabel(pts, labels, anchors, evidence=ev, keep=keep, **kw)
                        assert np.array_equal(got, ref)


def test_compiled_part_distances_match_the_numpy_path_within_the_reach():
    from posedrift.labelling import _relabel

    if _relabel._ckernels is None:
        pytest.skip("the compiled kernels are not built (no C compiler at install)")
    rng = np.random.default_rng(13)
    for pts in _clouds():
        graph = geodesic_graph(pts)
        labels = rng.integers(-1, 15, size=len(pts))
        labels[labels == 3] = 4  # a part without points: its anchors take the nearest point
        for anchors in _anchor_sets(pts, rng):
            reach = rng.uniform(0.0, 0.4, size=15)
            reach[2] = np.nan  # exact distances for that part
            for lab in (None, labels):
                exact = _relabel._part_distances(graph, pts, anchors, lab, compiled=False)
                assert np.array_equal(_relabel._part_distances(graph, pts, anchors, lab), exact)
                got = _relabel._part_distances(graph, pts, anchors, lab, reach)
                limit = np.broadcast_to(
                    np.where(np.isnan(reach), np.inf, reach)[:, None], got.shape
                )
                within = exact <= limit
                assert np.array_equal(got[within], exact[within])
                beyond = ~within & np.isfinite(exact)
                assert beyond.any()
                assert (got[beyond] > limit[beyond]).all()
                assert (got[beyond] >= exact[beyond]).all()  # the length of some path
                assert np.array_equal(np.isinf(got), np.isinf(exact))
    # Anchors on points: searches that start at 0.
    on_points = _relabel._part_distances(graph, pts, pts[:15], None)
    assert (on_points[np.arange(15), np.arange(15)] == 0).all()
    assert np.array_equal(
        on_points, _relabel._part_distances(graph, pts, pts[:15], None, compiled=False)
    )
    # No anchor at all: every part infinitely far.
    none = np.full((15, 3), np.nan)
    assert np.isinf(_relabel._part_distances(graph, pts, none, None)).all()
    assert np.isinf(_relabel._part_distances(graph, pts, none, None, compiled=False)).all()
    m, n = graph.matrix, len(pts)
    with pytest.raises(ValueError, match="buffer 'out'"):
        _relabel._ckernels.part_distances(
            pts, n, none, 15, 1, np.empty(0), np.empty(0), m.indptr, m.indices, m.data,
            np.empty((14, n)),
        )  # fmt: skip
    bad = m.indices.copy()
    bad[0] = 10**6
    with pytest.raises(ValueError, match="invalid graph"):
        _relabel._ckernels.part_distances(
            pts, n, pts[:15], 15, 1, np.empty(0), np.empty(0), m.indptr, bad, m.data,
            np.empty((15, n)),
        )  # fmt: skip
    with pytest.raises(ValueError, match="buffer 'idx'"):
        _relabel._ckernels.knn(pts, n, 2, np.empty((n, 2)), np.empty((n, 1), dtype=np.int64))
