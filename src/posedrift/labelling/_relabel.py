"""The labelling template set (the paper's Algorithm 2): geodesic relabelling of tracked points.

A k-nearest-neighbour graph over the labelled points, Dijkstra geodesic distances
from each part's joint ``J_j``, and the likelihood

``P(d_geo(v_i, J_j) | D_j H) = 1 / (1 + exp(alpha (d_geo(v_i, J_j) - D_j H)))``.

The paper takes the label of highest ``P``. Here ``P`` multiplies the label
evidence carried over by the registration (the CPD posterior, or the labels
themselves), so that it acts as a geodesic gate: a point keeps its tracked label
unless it lies geodesically too far from that part, and then it takes the most
likely part that can reach it. With uniform evidence this is exactly the paper's rule.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from scipy import sparse

from posedrift._stats import median
from posedrift._validation import check_points, check_scalar
from posedrift.skeleton import PART_NAMES

try:  # the compiled kernels are optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.labelling import _ckernels  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _ckernels = None


_Z_CLIP = 50.0  # the sigmoid's exponent is clipped to [-50, 50] (relabel)


@dataclass(frozen=True)
class GeodesicGraph:
    """A symmetric k-NN graph over points with edge lengths in metres.

    Attributes
    ----------
    matrix : scipy.sparse.csr_matrix, (N, N)
        Edge lengths (symmetric).
    rows, cols : (E,) int
        Edge end points (each undirected edge once, ``rows < cols``).
    lengths : (E,) float
    spacing : float
        Median nearest-neighbour distance (metres).
    """

    matrix: sparse.csr_matrix
    rows: np.ndarray
    cols: np.ndarray
    lengths: np.ndarray
    spacing: float


def geodesic_graph(
    points: np.ndarray,
    *,
    k: int = 6,
    max_edge_factor: float = 2.2,
    max_edge: float | None = None,
    depth_step: float | None = 0.06,
    compiled: bool = True,
) -> GeodesicGraph:
    """The k-NN graph of Algorithm 2, step 1, cut where edges jump.

    Edges longer than ``max_edge_factor`` times the median nearest-neighbour spacing
    (or ``max_edge`` metres) are dropped, and so are edges whose depth (``z``) change
    exceeds ``depth_step`` while their image-plane length is shorter than their depth
    change (an arm in front of the torso), so that limbs do not short-circuit.

    Parameters
    ----------
    points : (N, 3) float
        Camera-frame points, metres.
    k : int
        Neighbours per point.
    max_edge_factor : float
    max_edge : float, optional
    depth_step : float or None
        ``None`` disables the depth-discontinuity cut.
    compiled : bool
        Use the compiled k-NN and graph kernels where built (``False`` forces their
        NumPy and SciPy twin; the two give the same graph).

    Returns
    -------
    GeodesicGraph
    """
    points = check_points(points, "points", caller="geodesic_graph", min_points=2)
    if compiled and _ckernels is not None:
        return _graph_compiled(points, k, max_edge_factor, max_edge, depth_step)
    return _graph_numpy(points, k, max_edge_factor, max_edge, depth_step)


def _neighbours(points: np.ndarray, kk: int, compiled: bool) -> tuple[np.ndarray, np.ndarray]:
    """``cKDTree(points).query(points, k=kk)`` as (N, kk) arrays; the compiled kernel
    gives the same doubles and, but for ties in distance, the same indices."""
    n = len(points)
    if not compiled or _ckernels is None:
        from scipy.spatial import cKDTree

        dist, idx = cKDTree(points).query(points, k=kk)
        return dist.reshape(n, kk), idx.reshape(n, kk)
    dist, idx = np.empty((n, kk)), np.empty((n, kk), dtype=np.int64)
    _ckernels.knn(points, n, kk, dist, idx)
    return dist, idx


def _edge_limit(nearest: np.ndarray, max_edge_factor: float, max_edge: float | None):
    """(median of the nearest-neighbour distances ``nearest``, longest edge kept)."""
    spacing = median(nearest)
    limit = max_edge if max_edge is not None else max_edge_factor * max(spacing, 1e-6)
    return spacing, limit


def _graph_compiled(points, k, max_edge_factor, max_edge, depth_step) -> GeodesicGraph:
    """:func:`geodesic_graph` by the compiled k-NN and CSR kernels (the same graph)."""
    n = len(points)
    kk = min(k + 1, n)
    points = np.ascontiguousarray(points)
    dist, idx = _neighbours(points, kk, compiled=True)
    spacing, limit = _edge_limit(dist[:, 1], max_edge_factor, max_edge)
    indptr = np.empty(n + 1, dtype=np.int32)
    indices = np.empty(2 * n * (kk - 1), dtype=np.int32)
    data = np.empty(2 * n * (kk - 1))
    step = np.nan if depth_step is None else float(depth_step)
    nnz = _ckernels.graph_csr(points, n, kk, dist, idx, limit, step, indptr, indices, data)
    indices, data = indices[:nnz], data[:nnz]
    matrix = sparse.csr_matrix((data, indices, indptr), shape=(n, n))
    # Each undirected edge once, rows < cols, in (row, col) order: the upper triangle.
    rows = np.repeat(np.arange(n), np.diff(indptr))
    upper = indices > rows
    return GeodesicGraph(
        matrix=matrix,
        rows=rows[upper],
        cols=indices[upper].astype(np.int64),
        lengths=data[upper],
        spacing=spacing,
    )


def _graph_numpy(points, k, max_edge_factor, max_edge, depth_step) -> GeodesicGraph:
    """The NumPy twin of :func:`_graph_compiled`."""
    n = len(points)
    kk = min(k + 1, n)
    dist, idx = _neighbours(points, kk, compiled=False)
    dist, idx = dist[:, 1:], idx[:, 1:]
    spacing, limit = _edge_limit(dist[:, 0], max_edge_factor, max_edge)
    cols = idx.ravel()
    lengths = dist.ravel()
    keep = lengths <= limit  # a missing neighbour (k >= n) has an infinite distance
    keep &= cols < n
    edge = np.flatnonzero(keep)
    rows = edge // (kk - 1)
    cols, lengths = cols[edge], lengths[edge]
    keep = rows != cols  # a duplicate point may list its own index: no self-loops
    rows, cols, lengths = rows[keep], cols[keep], lengths[keep]
    if depth_step is not None and len(rows):
        dz = np.abs(points[cols, 2] - points[rows, 2])
        steep = np.flatnonzero(dz > depth_step)
        if len(steep):
            a, b = points[rows[steep]], points[cols[steep]]
            dxy = np.hypot(b[:, 0] - a[:, 0], b[:, 1] - a[:, 1])
            cut = np.ones(len(rows), dtype=bool)
            cut[steep[dz[steep] > dxy]] = False
            rows, cols, lengths = rows[cut], cols[cut], lengths[cut]
    lo, hi = np.minimum(rows, cols), np.maximum(rows, cols)
    key = lo * n + hi
    _, first = np.unique(key, return_index=True)
    lo, hi, lengths = lo[first], hi[first], lengths[first]
    lengths = np.maximum(lengths, 1e-9)
    matrix = _symmetric_csr(lo, hi, lengths, n)
    return GeodesicGraph(matrix=matrix, rows=lo, cols=hi, lengths=lengths, spacing=spacing)


def _symmetric_csr(lo: np.ndarray, hi: np.ndarray, lengths: np.ndarray, n: int):
    """The canonical CSR matrix (sorted indices) with ``lengths`` at ``(lo, hi)`` and ``(hi, lo)``.

    Equal to ``coo_matrix(...).tocsr()`` of the same entries (no duplicates), built
    without the generic conversion.
    """
    r = np.concatenate([lo, hi])
    c = np.concatenate([hi, lo])
    order = np.argsort(r * n + c, kind="stable")
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(np.bincount(r, minlength=n), out=indptr[1:])
    return sparse.csr_matrix(
        (np.concatenate([lengths, lengths])[order], c[order].astype(np.int32), indptr),
        shape=(n, n),
    )


def geodesic_distances(
    graph: GeodesicGraph, points: np.ndarray, anchors: np.ndarray, labels: np.ndarray | None = None
) -> np.ndarray:
    """Dijkstra distances ``(J, N)`` from each part's anchor(s) (Algorithm 2, step 2).

    Parameters
    ----------
    graph : GeodesicGraph
    points : (N, 3) float
    anchors : (J, 3) or (J, K, 3) float
        One anchor per part, or K anchors per part (e.g. points along its bone);
        a part's distance is the smallest over its anchors. NaN anchors are skipped.
    labels : (N,) int, optional
        Where given, each anchor's source vertex is the nearest point carrying its
        part's label (if the part has points), else the nearest point.

    Returns
    -------
    distances : (J, N) float
        The Euclidean gap from an anchor to its source vertex is included.
        Unreachable points and parts without anchors give ``inf``.
    """
    return _part_distances(graph, points, anchors, labels)


def _part_distances(
    graph: GeodesicGraph,
    points: np.ndarray,
    anchors: np.ndarray,
    labels: np.ndarray | None,
    reach: np.ndarray | None = None,
    compiled: bool = True,
) -> np.ndarray:
    """:func:`geodesic_distances`, optionally exact only up to each part's ``reach``.

    With ``reach`` (J,) metres, a part's distance is exact where it is at most
    ``reach[j]``; elsewhere it is the length of some path, above ``reach[j]`` (finite
    exactly where the point is reachable), which lets the searches stop early.
    ``compiled``: the compiled kernel where built (the same doubles as the code below).
    """
    anchors = np.asarray(anchors, dtype=float)
    if anchors.ndim == 2:
        anchors = anchors[:, None, :]
    n_parts, k = anchors.shape[:2]
    flat = anchors.reshape(-1, 3)
    if compiled and _ckernels is not None and len(points):
        # The same doubles in one compiled call (the sources, one search per part).
        matrix = graph.matrix
        out = np.empty((n_parts, len(points)))
        _ckernels.part_distances(
            np.ascontiguousarray(points, dtype=np.float64),
            len(points),
            np.ascontiguousarray(flat),
            len(flat),
            k,
            np.empty(0) if labels is None else np.ascontiguousarray(labels, dtype=np.int64),
            np.empty(0) if reach is None else np.ascontiguousarray(reach, dtype=np.float64),
            np.ascontiguousarray(matrix.indptr, dtype=np.int32),
            np.ascontiguousarray(matrix.indices, dtype=np.int32),
            np.ascontiguousarray(matrix.data, dtype=np.float64),
            out,
        )
        return out
    from scipy.sparse.csgraph import dijkstra

    part_of = np.repeat(np.arange(n_parts), k)
    valid = np.flatnonzero(np.isfinite(flat).all(axis=1))
    out = np.full((n_parts, len(points)), np.inf)
    if len(valid) == 0:
        return out
    part_of = part_of[valid]
    sources, gap = _anchor_sources(points, flat[valid], part_of, labels)
    # One search per part from an extra vertex joined to its anchors' sources by their
    # gaps (the shortest where anchors share a source): the same doubles as the
    # compiled search, exact everywhere (the reach only lets that one stop early).
    n = len(points)
    key = part_of * n + sources
    order = np.lexsort((gap, key))
    first = order[np.r_[True, key[order][1:] != key[order][:-1]]]
    parts = np.unique(part_of)
    extra = n + np.searchsorted(parts, part_of[first])
    matrix = graph.matrix.tocoo()
    rows = np.concatenate([matrix.row, extra])
    cols = np.concatenate([matrix.col, sources[first]])
    lengths = np.concatenate([matrix.data, gap[first]])
    size = n + len(parts)
    # Built as CSR directly: the gaps may be 0, which a conversion could drop.
    by_row = np.argsort(rows, kind="stable")
    indptr = np.zeros(size + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=size), out=indptr[1:])
    joined = sparse.csr_matrix((lengths[by_row], cols[by_row], indptr), shape=(size, size))
    out[parts] = dijkstra(joined, directed=True, indices=n + np.arange(len(parts)))[:, :n]
    return out


def _anchor_sources(
    points: np.ndarray, anchors: np.ndarray, part_of: np.ndarray, labels: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Each anchor's source vertex and its Euclidean gap to it (see geodesic_distances)."""
    # Squared distances (A, N), summed over x, y, z in that order.
    d2 = np.subtract.outer(anchors[:, 0], points[:, 0])
    d2 *= d2
    for axis in (1, 2):
        step = np.subtract.outer(anchors[:, axis], points[:, axis])
        step *= step
        d2 += step
    if labels is not None:
        own = labels[None, :] == part_of[:, None]
        has = own.any(axis=1)
        d2[~(own | ~has[:, None])] = np.inf
    sources = np.argmin(d2, axis=1)
    gap = np.sqrt(d2[np.arange(len(sources)), sources])
    return sources, gap


def row_shares(values: np.ndarray, total: np.ndarray, eps: float) -> np.ndarray:
    """``values (N, K)`` over their row sums ``total (N, 1)``; uniform rows where a sum
    is at most ``eps``."""
    full = total > eps
    if full.all():  # the usual case: the same quotients, without the masking
        return values / total
    return np.where(full, values / np.where(full, total, 1.0), 1.0 / values.shape[1])


def relabel(
    points: np.ndarray,
    labels: np.ndarray,
    part_joints: np.ndarray,
    *,
    height: float,
    ratios: np.ndarray,
    alpha: float = 60.0,
    k: int = 6,
    evidence: np.ndarray | None = None,
    evidence_floor: float = 0.05,
    graph: GeodesicGraph | None = None,
    keep_plausible: bool = True,
    return_likelihood: bool = False,
):
    """Algorithm 2 (labelling template set): relabel points by geodesic reach.

    Parameters
    ----------
    points : (N, 3) float
        The labelled point set ``S_D`` (metres).
    labels : (N,) int
        Current part of each point (``PART_NAMES`` index; -1 unknown).
    part_joints : (15, 3) or (15, K, 3) float
        ``J_j``, the joint (anchor) of each part, metres, or K anchors per part
        (points along its bone: the distance is then to the nearest); NaN for a
        part not known.
    height : float
        Stature ``H`` in metres.
    ratios : (15,) float
        ``D_j``: the geodesic reach of each part from its joint, as a fraction of ``H``.
    alpha : float
        Sigmoid steepness in 1/m (the paper's alpha).
    k : int
        Neighbours in the k-NN graph.
    evidence : (N, 15) float, optional
        Label evidence per point (e.g. the registration's posterior); defaults to
        ``labels`` one-hot.
    evidence_floor : float
        Added to normalized evidence so that a point can change part when its
        tracked part cannot reach it.
    graph : GeodesicGraph, optional
        A graph already built on ``points``.
    keep_plausible : bool
        Keep a point's tracked label (its evidence's argmax) wherever that part's
        likelihood is at least 0.5, and relabel only the others (the default). With
        False every point takes the argmax of evidence times likelihood.
    return_likelihood : bool
        Also return the ``(N, 15)`` likelihood ``P``.

    Returns
    -------
    new_labels : (N,) int
    likelihood : (N, 15) float
        Only with ``return_likelihood``.

    Examples
    --------
    >>> import numpy as np
    >>> line = np.column_stack([np.linspace(0, 1, 21), np.zeros(21), np.zeros(21)])
    >>> labels = np.zeros(21, int); labels[3] = 1          # one stray label
    >>> joints = np.full((15, 3), np.nan); joints[0] = (0, 0, 0); joints[1] = (1, 0, 0)
    >>> ratios = np.zeros(15); ratios[:2] = 0.5
    >>> relabel(line, labels, joints, height=1.0, ratios=ratios, alpha=50.0)[:6]
    array([0, 0, 0, 0, 0, 0])
    """
    points = check_points(points, "points", caller="relabel", min_points=1)
    labels = np.asarray(labels).astype(np.int64).reshape(-1)
    if labels.shape != (len(points),):
        raise ValueError(
            f"The 'labels' argument of relabel must have shape ({len(points)},). "
            f"Got {labels.shape} instead."
        )
    part_joints = np.asarray(part_joints, dtype=float)
    ratios = np.asarray(ratios, dtype=float).reshape(-1)
    n_parts = len(part_joints)
    if part_joints.shape[-1] != 3 or part_joints.ndim not in (2, 3) or ratios.shape != (n_parts,):
        raise ValueError(
            "The 'part_joints' (J, 3) and 'ratios' (J,) arguments of relabel must agree. "
            f"Got {part_joints.shape} and {ratios.shape}."
        )
    height = check_scalar(height, "height", low=0.0, caller="relabel")
    alpha = check_scalar(alpha, "alpha", low=0.0, caller="relabel")
    if len(points) < 2:
        out = labels.copy()
        return (out, np.ones((len(points), n_parts))) if return_likelihood else out
    if graph is None:
        graph = geodesic_graph(points, k=k)
    # Beyond D_j H + _Z_CLIP / alpha the clipped sigmoid is flat: the distances need not be
    # exact there (the searches stop early), only finite where the point is reachable.
    reach = ratios * height + _Z_CLIP / alpha
    geo = _part_distances(graph, points, part_joints, labels, reach).T  # (N, J)
    with np.errstate(over="ignore", invalid="ignore"):
        z = np.clip(alpha * (geo - ratios[None, :] * height), -_Z_CLIP, _Z_CLIP)
        z = np.where(np.isfinite(geo), z, _Z_CLIP)
        likelihood = 1.0 / (1.0 + np.exp(z))
    if evidence is None:
        evidence = np.zeros((len(points), n_parts))
        known = (labels >= 0) & (labels < n_parts)
        evidence[np.nonzero(known)[0], labels[known]] = 1.0
    else:
        evidence = np.asarray(evidence, dtype=float)
        if evidence.shape != (len(points), n_parts):
            raise ValueError(
                f"The 'evidence' argument of relabel must have shape ({len(points)}, {n_parts}). "
                f"Got {evidence.shape} instead."
            )
    total = evidence.sum(axis=1, keepdims=True)
    # Rows without evidence (registration outliers) fall back on the given labels.
    weak = total[:, 0] <= 1e-6
    known = (labels >= 0) & (labels < n_parts)
    fill = weak & known
    if fill.any():
        evidence = evidence.copy()
        evidence[fill] = 0.0
        evidence[np.nonzero(fill)[0], labels[fill]] = 1.0
        total = evidence.sum(axis=1, keepdims=True)
    norm = row_shares(evidence, total, 1e-6)
    score = (norm + evidence_floor) * likelihood
    new = np.argmax(norm, axis=1)
    if not keep_plausible:
        new = np.argmax(score, axis=1)
    else:
        # Keep each tracked label its part can reach; relabel only the implausible ones.
        # A point cut off from its part's graph component has no geodesic evidence.
        rows = np.arange(len(new))
        implausible = (likelihood[rows, new] < 0.5) & np.isfinite(geo[rows, new])
        new[implausible] = np.argmax(score[implausible], axis=1)
    # Where no part reaches a point, keep its evidence.
    stuck = score.max(axis=1) < 1e-6
    if stuck.any():
        new[stuck] = np.where(labels[stuck] >= 0, labels[stuck], np.argmax(norm[stuck], axis=1))
    return (new, likelihood) if return_likelihood else new


def merge_islands(
    labels: np.ndarray,
    graph: GeodesicGraph,
    parts: Sequence[int],
    *,
    max_points: int = 8,
    max_share: float = 0.34,
) -> np.ndarray:
    """Small pieces of a part, cut off from its main piece, take their neighbours' label.

    Beyond the paper. A part's points should form one piece of the graph: a few
    points carrying its label elsewhere (a forearm pointed at the camera, in front of
    the hidden elbow, partly labelled upper arm) are mislabelled, and a boundary they
    form with the next part is a joint where none is. For each of ``parts``, the
    pieces of the graph joined by edges between its own points are found; every piece
    but the largest, where it has at most ``max_points`` points and at most
    ``max_share`` of the part's, takes the label most of its edges to other points
    lead to (a piece with no such edge keeps its label).

    Parameters
    ----------
    labels : (N,) int
        Part of each point (labels outside 0-14 are left alone).
    graph : GeodesicGraph
        The points' graph (:func:`geodesic_graph`).
    parts : sequence of int
        The parts whose islands are merged.
    max_points : int
        Largest piece merged.
    max_share : float
        Largest piece merged, as a share of the part's points.

    Returns
    -------
    (N,) array of the labels' dtype
        A new array; ``labels`` itself where nothing changed.

    Examples
    --------
    A row of points, the second labelled 1 between points labelled 0, and a piece of
    label 1 at the end:

    >>> import numpy as np
    >>> points = np.column_stack([np.arange(8) * 0.02, np.zeros(8), np.full(8, 2.0)])
    >>> labels = np.array([0, 1, 0, 0, 0, 1, 1, 1])
    >>> graph = geodesic_graph(points, k=2)
    >>> merge_islands(labels, graph, [1]).tolist()
    [0, 0, 0, 0, 0, 1, 1, 1]
    """
    labels = np.asarray(labels)
    rows, cols = graph.rows, graph.cols
    n_labels = len(PART_NAMES)
    out = labels
    for part in parts:
        own = labels == part
        members = np.flatnonzero(own)
        if len(members) < 2:
            continue
        inside = own[rows] & own[cols]
        local = np.full(len(labels), -1, dtype=np.intp)
        local[members] = np.arange(len(members))
        piece = _pieces(len(members), local[rows[inside]], local[cols[inside]])
        sizes = np.bincount(piece)
        small = (sizes > 0) & (sizes <= max_points) & (sizes <= max_share * len(members))
        small[np.argmax(sizes)] = False
        if not small.any():
            continue
        # Each edge from a small piece to a point of another label votes for that label.
        island = np.zeros(len(labels), dtype=bool)
        island[members[small[piece]]] = True
        leaving = island[rows] != island[cols]
        inner = np.where(island[rows[leaving]], rows[leaving], cols[leaving])
        other = labels[np.where(island[rows[leaving]], cols[leaving], rows[leaving])]
        valid = (other >= 0) & (other < n_labels) & (other != part)
        inner, other = inner[valid], other[valid]
        if not len(inner):
            continue
        votes = np.zeros((len(sizes), n_labels), dtype=np.intp)
        np.add.at(votes, (piece[local[inner]], other), 1)
        if out is labels:
            out = labels.copy()
        for p in np.flatnonzero(small & votes.any(axis=1)):
            out[members[piece == p]] = int(np.argmax(votes[p]))
    return out


def _pieces(count: int, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Connected components of ``count`` nodes joined by the edges ``a[i] - b[i]``: each
    node's smallest connected node. Minimum labels are spread along the edges and
    shortcut (pointer jumping) until nothing changes: a few NumPy passes for the tens
    of points of one part, where building a sparse graph for SciPy took five times as long."""
    piece = np.arange(count)
    while True:
        low = np.minimum(piece[a], piece[b])
        spread = piece.copy()
        np.minimum.at(spread, a, low)
        np.minimum.at(spread, b, low)
        spread = spread[spread]
        if np.array_equal(spread, piece):
            return piece
        piece = spread
