"""Mean-shift modes of the labelled body parts (paper, Section 3.4)."""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_points, check_scalar


def part_modes(
    points: np.ndarray,
    labels: np.ndarray,
    *,
    bandwidth: float = 0.08,
    weights: np.ndarray | None = None,
    n_parts: int = 15,
    max_iter: int = 20,
    tol: float = 1e-4,
    return_counts: bool = False,
):
    """The mode of each part's points by Gaussian mean shift, all parts at once.

    Each part starts from its (weighted) mean and climbs the kernel density of its
    own points: ``m <- sum_i w_i K(p_i - m) p_i / sum_i w_i K(p_i - m)`` with
    ``K(r) = exp(-|r|^2 / (2 bandwidth^2))``.

    Parameters
    ----------
    points : (N, 3) float
        Metres.
    labels : (N,) int
        Part index per point; negative or ``>= n_parts`` ignored.
    bandwidth : float
        Kernel width in metres.
    weights : (N,) float, optional
        Non-negative point weights (e.g. label posterior).
    n_parts : int
    max_iter : int
    tol : float
        Stop when no mode moves more than ``tol`` metres.
    return_counts : bool
        Also return the weighted point count of each part.

    Returns
    -------
    modes : (n_parts, 3) float
        NaN for parts with no points.
    counts : (n_parts,) float
        Only with ``return_counts``.

    Examples
    --------
    >>> import numpy as np
    >>> pts = np.array([[0, 0, 0], [0.01, 0, 0], [1.0, 0, 0]])
    >>> np.round(part_modes(pts, np.array([0, 0, 0]), bandwidth=0.05, n_parts=2), 3)
    array([[0.005, 0.   , 0.   ],
           [  nan,   nan,   nan]])
    """
    points = check_points(points, "points", caller="part_modes", min_points=0)
    labels = np.asarray(labels).astype(np.int64).reshape(-1)
    if labels.shape != (len(points),):
        raise ValueError(
            f"The 'labels' argument of part_modes must have shape ({len(points)},). "
            f"Got {labels.shape} instead."
        )
    bandwidth = check_scalar(bandwidth, "bandwidth", low=0.0, caller="part_modes")
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=float).reshape(-1)
    if w.shape != (len(points),) or (w < 0).any():
        raise ValueError(
            f"The 'weights' argument of part_modes must be ({len(points)},) non-negative. "
            f"Got shape {w.shape}."
        )
    ok = (labels >= 0) & (labels < n_parts)
    p, lab, w = points[ok], labels[ok], w[ok]
    counts = np.bincount(lab, weights=w, minlength=n_parts)
    modes = np.full((n_parts, 3), np.nan)
    have = counts > 0
    if not have.any():
        return (modes, counts) if return_counts else modes
    for d in range(3):
        modes[have, d] = (
            np.bincount(lab, weights=w * p[:, d], minlength=n_parts)[have] / counts[have]
        )
    inv2h2 = 0.5 / bandwidth**2
    # Only the parts with points, with column-major state: coordinates (3, M) and modes
    # (3, parts); one bincount per iteration over [kernel, kernel * x, kernel * y,
    # kernel * z] (each bin sums its points in input order, as separate bincounts would).
    live = np.flatnonzero(have)
    n_live = len(live)
    slot = np.zeros(n_parts, dtype=np.intp)
    slot[live] = np.arange(n_live)
    lab = slot[lab]
    coords = np.ascontiguousarray(p.T)
    centre = np.ascontiguousarray(modes[live].T)
    groups = (lab[None, :] + n_live * np.arange(4)[:, None]).ravel()
    weighted = np.empty((4, len(lab)))
    kernel = weighted[0]
    diff = np.empty_like(coords)
    for _ in range(max_iter):
        np.subtract(coords, np.take(centre, lab, axis=1), out=diff)
        diff *= diff
        r2 = diff[0] + diff[1]
        r2 += diff[2]
        np.negative(r2, out=r2)
        r2 *= inv2h2
        np.exp(r2, out=kernel)
        if weights is not None:
            np.multiply(w, kernel, out=kernel)
        np.multiply(coords, kernel, out=weighted[1:])
        sums = np.bincount(groups, weights=weighted.ravel(), minlength=4 * n_live)
        sums = sums.reshape(4, n_live)
        den = sums[0]
        move = den > 1e-12
        if move.all():
            new = sums[1:] / den
        elif move.any():
            new = centre.copy()
            new[:, move] = sums[1:, move] / den[move]
        else:
            break
        shift = float(np.abs(new - centre).max())
        centre = new
        if shift < tol:
            break
    modes[live] = centre.T
    return (modes, counts) if return_counts else modes
