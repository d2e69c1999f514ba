"""Uniform downsampling of a point cloud to a target count (paper, Section 3.2)."""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_points, check_rng, check_scalar

try:  # the compiled kernel is optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.points import _cpoints  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _cpoints = None


def _voxel_centroids(
    points: np.ndarray, size: float, compiled: bool = True
) -> tuple[np.ndarray, np.ndarray]:
    """Centroid of the points in each occupied voxel, and the voxel of each point.

    Voxels are numbered in increasing order of their flat grid index (as
    ``np.unique`` of the flat indices would); the centroids sum each voxel's points in
    input order. The compiled kernel, where built, gives the same doubles.
    """
    if compiled and _cpoints is not None and len(points):
        points = np.ascontiguousarray(points, dtype=np.float64)
        centroids, inverse = np.empty((len(points), 3)), np.empty(len(points), dtype=np.int64)
        count = _cpoints.voxel_centroids(points, len(points), float(size), centroids, inverse)
        return centroids[:count], inverse
    # Column-wise reductions: much faster than axis-0 reductions of an (N, 3) array.
    low = np.array([points[:, d].min() for d in range(3)]) if len(points) else np.zeros(3)
    keys = np.floor((points - low) / size).astype(np.int64)
    dims = np.array([keys[:, d].max() for d in range(3)]) + 1 if len(points) else np.ones(3, int)
    flat = (keys[:, 0] * dims[1] + keys[:, 1]) * dims[2] + keys[:, 2]
    cells = int(dims[0] * dims[1] * dims[2])
    if cells <= 16 * len(points) + 4096:
        # Occupancy by counting over the grid: no sort.
        counts = np.bincount(flat, minlength=cells)
        occupied = np.flatnonzero(counts)
        rank = np.zeros(cells, dtype=np.intp)
        rank[occupied] = np.arange(len(occupied))
        inverse = rank[flat]
        counts = counts[occupied]
    else:
        _, inverse, counts = np.unique(flat, return_inverse=True, return_counts=True)
    k = len(counts)
    centroids = np.empty((k, 3))
    for d in range(3):
        centroids[:, d] = np.bincount(inverse, weights=points[:, d], minlength=k) / counts
    return centroids, inverse


def downsample(
    points: np.ndarray,
    n: int = 400,
    *,
    voxel_size: float | None = None,
    rng: int | np.random.Generator | None = 0,
    return_voxel_size: bool = False,
):
    """Downsample a point cloud to ``n`` points of even spatial density.

    A voxel grid sized so that between ``n`` and ``1.1 n`` cells are occupied
    replaces each cell by the centroid of its points; the few cells beyond ``n`` are
    dropped at random (seeded), so the density stays even over the surface and the
    count is exactly ``min(n, len(points))``.

    Parameters
    ----------
    points : (N, 3) float
        Metres.
    n : int
        Target count.
    voxel_size : float, optional
        A first guess of the cell size in metres (e.g. the previous frame's);
        estimated from the cloud's extent where not given.
    rng : int, Generator or None
        Seeds the choice of cells (deterministic for an int).
    return_voxel_size : bool
        Also return the cell size used (a good guess for the next frame).

    Returns
    -------
    sampled : (min(n, N), 3) float
    voxel_size : float
        Only with ``return_voxel_size``.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.random.default_rng(0).uniform(size=(5000, 3)) * [1, 1, 0.01]
    >>> downsample(pts, 400).shape
    (400, 3)
    """
    points = check_points(points, "points", caller="downsample", min_points=0)
    n = check_scalar(n, "n", low=1, include_low=True, integer=True, caller="downsample")
    return downsample_checked(points, n, voxel_size, check_rng(rng), return_voxel_size)


def downsample_checked(
    points: np.ndarray,
    n: int,
    voxel_size: float | None,
    gen: np.random.Generator,
    return_voxel_size: bool,
):
    """:func:`downsample` of arguments already checked: C-contiguous finite ``(N, 3)``
    float64 points (the tracker's back-projected pixels), an int and a Generator."""
    if len(points) <= n:
        out = points.copy()
        return (out, voxel_size or 0.0) if return_voxel_size else out
    if voxel_size is None or not voxel_size > 0:
        # A 2.5-D surface: area ~ (largest extent) x (second extent); cells of area/n.
        ext = np.sort(np.ptp(points, axis=0))[::-1]
        area = max(ext[0] * ext[1], 1e-12)
        voxel_size = float(np.sqrt(area / n)) * 0.5
    size = float(voxel_size)
    centroids, _ = _voxel_centroids(points, size)
    for _ in range(12):
        k = len(centroids)
        if k < n:
            size *= 0.98 * np.sqrt(k / n)
        elif k > 1.1 * n:
            size *= np.sqrt(k / (1.04 * n))
        else:
            break
        centroids, _ = _voxel_centroids(points, size)
    if len(centroids) < n:  # Tiny clouds with many duplicates: fall back to the points.
        centroids = points
    chosen = np.sort(gen.choice(len(centroids), n, replace=False))
    out = centroids[chosen]
    return (out, size) if return_voxel_size else out
