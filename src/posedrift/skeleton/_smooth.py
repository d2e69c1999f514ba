"""Joint paths smoothed in time: a recording after the fact, or a stream with a latency.

The tracker is causal: each frame's joints come from that frame and the past. A
recording that is analysed after the fact can also use the frames that follow (a live
stream the few that a latency allows), and a smoother centred on each frame then
removes the frame-to-frame jitter of the fitted joints without the lag of a causal
filter. Each joint's path is fitted, around each frame, by
a quadratic in time weighted by a Gaussian (a Savitzky-Golay filter for irregular
timestamps): unlike a moving average it keeps the peaks of a movement, such as the
largest flexion of a knee, where a range of motion is measured. Written here because
SciPy's ``savgol_filter`` assumes regular samples and no gaps, and a recording has
frames without a pose.
"""

from __future__ import annotations

import numpy as np

_REACH = 3.0
"""Neighbours farther than this many ``sigma`` in time are left out (weights < 0.011)."""

_RIDGE = 1e-6
"""Ridge on the slope and curvature terms (relative to the summed weight): where a
frame has too few neighbours to fit a quadratic, the fit falls back towards a line or
the frame itself instead of failing."""

_TIME_TOLERANCE = 1e-6
"""Seconds by which two frames' times may differ from the window's edge and still count."""

_CHUNK = 4096
"""Frames smoothed at once (bounds the memory of long recordings)."""


def smooth_joints(joints, times, sigma: float, *, lag: float | None = None) -> np.ndarray:
    """Joint paths smoothed in time (local quadratic fits around each frame).

    Each finite joint position is replaced by the value at its frame's time of a
    quadratic fitted by weighted least squares to the same joint over the frames
    within ``3 * sigma`` seconds, with Gaussian weights of standard deviation
    ``sigma``; with ``lag``, only over the frames up to ``lag`` seconds after it,
    so that a live stream can be smoothed with that latency
    (:class:`posedrift.tracking.LiveSmoother`). Frames where a joint is unknown (NaN)
    stay unknown and split its path: nothing is smoothed across a frame without the
    joint (a person who left the view, a lost frame).

    Parameters
    ----------
    joints : (T, J, 3) array_like of float
        Joint positions over ``T`` frames (metres), NaN where unknown.
    times : (T,) array_like of float
        Each frame's time in seconds, non-decreasing (a recording's timestamps, or
        ``index / fps``).
    sigma : float
        Standard deviation of the weights, seconds; 0 returns the joints unchanged.
        0.1 s (three frames at 30 per second) is the value measured in
        ``docs/RESULTS.md``.
    lag : float, optional
        Seconds: the latest frame used is this long after the one smoothed (None:
        ``3 * sigma``, every frame of the window; 0: the past only).

    Returns
    -------
    (T, J, 3) ndarray of float
        A new array.

    Raises
    ------
    ValueError
        If the shapes do not match, ``times`` is not finite and non-decreasing, or
        ``sigma`` or ``lag`` is negative or not finite.

    Examples
    --------
    >>> t = np.arange(60) / 30.0
    >>> path = np.zeros((60, 1, 3)); path[:, 0, 0] = 0.5 * t**2
    >>> noisy = path + np.random.default_rng(0).normal(0, 0.01, path.shape)
    >>> err = lambda p: np.abs(p - path).mean()
    >>> bool(err(smooth_joints(noisy, t, 0.1)) < 0.6 * err(noisy))
    True
    """
    joints = np.array(joints, dtype=float)  # a copy: the result
    times = np.asarray(times, dtype=float)
    if joints.ndim != 3 or joints.shape[2] != 3:
        raise ValueError(f"'joints' must have shape (T, J, 3). Got {joints.shape}.")
    if times.shape != (len(joints),):
        raise ValueError(
            f"'times' must have one value per frame, shape ({len(joints)},). Got {times.shape}."
        )
    if not np.isfinite(times).all() or np.any(np.diff(times) < 0):
        raise ValueError("'times' must be finite and non-decreasing (seconds).")
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"'sigma' must be a non-negative number of seconds. Got {sigma}.")
    if lag is not None and not (np.isfinite(lag) and lag >= 0):
        raise ValueError(f"'lag' must be a non-negative number of seconds. Got {lag}.")
    if sigma == 0 or len(joints) < 2:
        return joints
    known = np.isfinite(joints).all(axis=2)  # (T, J)
    # Frames of one stretch of a joint's path share an id: the unknown frames before them.
    stretch = np.cumsum(~known, axis=0)
    lo = np.searchsorted(times, times - _REACH * sigma, side="left")
    ahead = _REACH * sigma if lag is None else min(lag, _REACH * sigma)
    # (The tolerance keeps a frame exactly ``lag`` later despite rounding: 2 / 30 s.)
    hi = np.searchsorted(times, times + ahead + _TIME_TOLERANCE, side="right")
    width = int((hi - lo).max())
    out = joints.copy()
    for start in range(0, len(joints), _CHUNK):
        rows = np.arange(start, min(start + _CHUNK, len(joints)))
        out[rows] = _fit_rows(joints, times, known, stretch, rows, lo[rows], hi[rows], width, sigma)
    out[~known] = np.nan
    return out


def _fit_rows(joints, times, known, stretch, rows, lo, hi, width, sigma) -> np.ndarray:
    """The smoothed joints ``(len(rows), J, 3)`` of frames ``rows``."""
    offsets = np.arange(width)
    idx = np.minimum(lo[:, None] + offsets, len(times) - 1)  # (R, W) neighbour frames
    x = (times[idx] - times[rows, None]) / sigma  # time in sigmas, (R, W)
    weight = np.exp(-0.5 * x * x) * (offsets < (hi - lo)[:, None])
    # Per joint: only its known neighbours on the same stretch of its path. (R, W, J)
    w = weight[:, :, None] * (known[idx] & (stretch[idx] == stretch[rows][:, None, :]))
    powers = x[:, :, None] ** np.arange(5)  # (R, W, 5): 1, x, ..., x^4
    moments = np.einsum("rwj,rwp->rjp", w, powers)  # (R, J, 5)
    normal = moments[:, :, np.array([[0, 1, 2], [1, 2, 3], [2, 3, 4]])]  # (R, J, 3, 3)
    normal += _RIDGE * moments[:, :, :1, None] * np.diag([0.0, 1.0, 1.0])
    normal += (moments[:, :, 0] == 0)[..., None, None] * np.eye(3)  # unknown here: solvable
    values = np.nan_to_num(joints[idx])  # (R, W, J, 3); unknown ones have zero weight
    rhs = np.einsum("rwj,rwp,rwjc->rjpc", w, powers[:, :, :3], values)  # (R, J, 3, 3)
    coefficients = np.linalg.solve(normal, rhs)  # (R, J, 3 terms, 3 coordinates)
    return coefficients[:, :, 0, :]
