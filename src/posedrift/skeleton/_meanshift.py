"""Mean-shift modes of the labelled body parts (paper, Section 3.4)."""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_points, check_scalar

try:  # the compiled kernel is optional: its NumPy twin gives the same modes
    from posedrift.skeleton import _cmeanshift  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _cmeanshift = None


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
    if ok.all():  # the usual case: no copies
        p, lab = points, labels
    else:
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
    live = have.copy()
    _shift_modes(
        p,
        lab,
        w,
        modes,
        live,
        scale=-0.5 / bandwidth**2,
        max_iter=max_iter,
        tol=tol,
        min_mass=1e-12,
        drop_lost=False,
    )
    return (modes, counts) if return_counts else modes


def _shift_modes(
    coords: np.ndarray,
    group: np.ndarray,
    weight: np.ndarray,
    centre: np.ndarray,
    live: np.ndarray,
    *,
    scale: float,
    max_iter: int,
    tol: float,
    min_mass: float,
    drop_lost: bool,
    compiled: bool = True,
) -> int:
    """Grouped Gaussian mean shift, in place: the one kernel behind every mode search.

    Each live group's ``centre`` row climbs the density of its own points (``coords``
    rows whose ``group`` is its index), weighted by ``weight * exp(scale * r^2)``. A
    group whose kernel mass falls to ``min_mass`` stays put, or with ``drop_lost``
    leaves ``live``. Stops after ``max_iter`` steps, when no group moved or when no
    centre moved more than ``tol`` metres. The compiled kernel (``_cmeanshift.c``)
    where it is built, else its NumPy twin (the same sums in the same order).

    Parameters
    ----------
    coords : (M, 3) float
    group : (M,) int
        In ``[0, G)``.
    weight : (M,) float
    centre : (G, 3) float
        Starting points; overwritten with the modes.
    live : (G,) bool
        The groups that climb; overwritten.

    Returns
    -------
    int
        Steps taken.
    """
    coords = np.ascontiguousarray(coords, dtype=np.float64)
    group = np.ascontiguousarray(group, dtype=np.int64)
    weight = np.ascontiguousarray(weight, dtype=np.float64)
    if (
        compiled
        and _cmeanshift is not None
        and centre.flags.c_contiguous
        and live.flags.c_contiguous
    ):
        return _cmeanshift.shift(
            coords,
            group,
            weight,
            centre,
            live.view(np.uint8),
            float(scale),
            int(max_iter),
            float(tol),
            float(min_mass),
            bool(drop_lost),
        )
    return _shift_modes_numpy(
        coords,
        group,
        weight,
        centre,
        live,
        scale=scale,
        max_iter=max_iter,
        tol=tol,
        min_mass=min_mass,
        drop_lost=drop_lost,
    )


def _shift_modes_numpy(
    coords, group, weight, centre, live, *, scale, max_iter, tol, min_mass, drop_lost
) -> int:
    """:func:`_shift_modes` in NumPy: one bincount per step over the live groups."""
    slots = np.flatnonzero(live)
    if len(slots) == 0 or max_iter < 1:
        return 0
    slot_of = np.full(len(live), -1, dtype=np.intp)
    slot_of[slots] = np.arange(len(slots))
    lab = slot_of[group]
    keep = lab >= 0
    lab, w = lab[keep], weight[keep]
    # Column-major state: coordinates (3, M') and centres (3, live); one bincount per
    # step over [kernel, kernel * x, kernel * y, kernel * z] (each bin sums its points
    # in input order, as the compiled kernel does).
    cols = np.ascontiguousarray(coords[keep].T)
    state = np.ascontiguousarray(centre[slots].T)
    alive = np.ones(len(slots), dtype=bool)
    n_live = len(slots)
    bins = (lab[None, :] + n_live * np.arange(4)[:, None]).ravel()
    weighted = np.empty((4, len(lab)))
    kernel = weighted[0]
    diff = np.empty_like(cols)
    step = 0
    while step < max_iter:
        step += 1
        np.subtract(cols, np.take(state, lab, axis=1), out=diff)
        diff *= diff
        r2 = diff[0] + diff[1]
        r2 += diff[2]
        r2 *= scale
        np.exp(r2, out=kernel)
        np.multiply(w, kernel, out=kernel)
        np.multiply(cols, kernel, out=weighted[1:])
        sums = np.bincount(bins, weights=weighted.ravel(), minlength=4 * n_live)
        sums = sums.reshape(4, n_live)
        move = alive & (sums[0] > min_mass)
        if drop_lost:
            alive = move
        if not move.any():
            break
        new = sums[1:, move] / sums[0, move]
        moved = float(np.abs(new - state[:, move]).max())
        state[:, move] = new
        if moved < tol:
            break
    centre[slots] = state.T
    live[slots] = alive
    return step
