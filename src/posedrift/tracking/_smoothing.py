"""Results smoothed in time: a recording after the fact, or a live stream with latency.

Both apply :func:`posedrift.skeleton.smooth_joints` (local quadratic fits over each
joint's path) to the joints of a sequence of :class:`FrameResult`; everything else a
result holds is kept, and the angles follow from the smoothed joints.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np

from posedrift.skeleton import smooth_joints
from posedrift.skeleton._smooth import _REACH, _TIME_TOLERANCE
from posedrift.tracking._result import FrameResult


def _check(sigma: float, lag: float | None, fps: float) -> None:
    if not (np.isfinite(sigma) and sigma >= 0):
        raise ValueError(f"'sigma' must be a non-negative number of seconds. Got {sigma}.")
    if lag is not None and not (np.isfinite(lag) and lag >= 0):
        raise ValueError(f"'lag' must be a non-negative number of seconds. Got {lag}.")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"'fps' must be positive. Got {fps}.")


def _smoothed(results: list[FrameResult], times: np.ndarray, sigma, lag) -> list[FrameResult]:
    joints = smooth_joints(np.stack([r.joints for r in results]), times, sigma, lag=lag)
    return [
        replace(r, joints=j) if np.isfinite(r.joints).any() else r
        for r, j in zip(results, joints, strict=True)
    ]


def smooth_results(
    results: Sequence[FrameResult],
    sigma: float,
    *,
    lag: float | None = None,
    fps: float = 30.0,
) -> list[FrameResult]:
    """A recording's results with their joints smoothed in time.

    :func:`posedrift.skeleton.smooth_joints` over the whole sequence: each joint's
    path is fitted, around each frame, by a quadratic in time over the frames within
    ``3 * sigma`` seconds before it and as far after it (``lag`` seconds at most,
    where given). For results already recorded (``posedrift track --smooth``); a live
    stream gets the same with :class:`LiveSmoother`. Frames without a pose stay so
    and split the paths. Everything but the joints (and the angles, computed from
    them) is kept.

    Parameters
    ----------
    results : sequence of FrameResult
        One sequence's results, in order.
    sigma : float
        Seconds; 0 returns the results as they are.
    lag : float, optional
        Seconds: use no frame later than this after the one smoothed (the latency a
        live stream would have); None uses the whole window.
    fps : float
        Frame rate for the frames' times where the results lack timestamps (or their
        timestamps decrease somewhere): frame ``index / fps``.

    Returns
    -------
    list of FrameResult
    """
    _check(sigma, lag, fps)
    results = list(results)
    if sigma == 0 or not results:
        return results
    times = np.array([np.nan if r.timestamp is None else r.timestamp for r in results])
    if not (np.isfinite(times).all() and np.all(np.diff(times) >= 0)):
        times = np.array([r.index for r in results], dtype=float) / fps
    return _smoothed(results, times, sigma, lag)


class LiveSmoother:
    """A live stream of results smoothed with a fixed latency.

    Give it each frame's result as the tracker returns it (:meth:`push`); it gives
    back the results that are final, each once the frames ``lag`` seconds after it
    have arrived, smoothed as :func:`smooth_results` with the same ``sigma`` and
    ``lag`` would smooth the whole recording. At the end of the stream, :meth:`flush`
    gives the rest. On the development clips two frames of latency (``lag=0.067`` at
    30 frames per second) kept most of what smoothing the whole recording gains
    (``docs/RESULTS.md``).

    Parameters
    ----------
    sigma : float
        Seconds (:func:`smooth_results`).
    lag : float
        Seconds of latency: how long after a frame its result is given back.
    fps : float
        Frame rate for results without timestamps (frame ``index / fps``).

    Examples
    --------
    >>> from posedrift.tracking import FrameResult, FrameStatus
    >>> smoother = LiveSmoother(sigma=0.1, lag=2 / 30)
    >>> out = []
    >>> for i in range(5):
    ...     result = FrameResult(i, FrameStatus.TRACKED, np.zeros((15, 3)), np.ones(15))
    ...     out += smoother.push(result)
    ...     print(i, [r.index for r in out])
    0 []
    1 []
    2 [0]
    3 [0, 1]
    4 [0, 1, 2]
    >>> [r.index for r in smoother.flush()]
    [3, 4]
    """

    def __init__(self, sigma: float = 0.1, lag: float = 2 / 30, *, fps: float = 30.0) -> None:
        _check(sigma, lag, fps)
        self.sigma, self.lag, self.fps = float(sigma), float(lag), float(fps)
        self._results: list[FrameResult] = []  # the window: raw results, oldest first
        self._times: list[float] = []
        self._given = 0  # how many of the window's results were given back

    def push(self, result: FrameResult) -> list[FrameResult]:
        """Add the newest frame's result; the results now final, oldest first.

        Raises
        ------
        ValueError
            If its time is before the last frame's.
        """
        time = result.index / self.fps if result.timestamp is None else float(result.timestamp)
        if self._times and time < self._times[-1]:
            raise ValueError(
                f"LiveSmoother: frame {result.index} is at {time:g} s, before the last "
                f"frame ({self._times[-1]:g} s): results must come in time order."
            )
        self._results.append(result)
        self._times.append(time)
        ready = sum(1 for t in self._times[self._given :] if t <= time - self.lag + _TIME_TOLERANCE)
        return self._give(ready)

    def flush(self) -> list[FrameResult]:
        """The results not given back yet, smoothed with the frames there are (the end)."""
        out = self._give(len(self._results) - self._given)
        self._results, self._times, self._given = [], [], 0
        return out

    def _give(self, count: int) -> list[FrameResult]:
        if count == 0:
            return []
        if self.sigma == 0:
            out = self._results[self._given : self._given + count]
        else:
            times = np.array(self._times)
            out = _smoothed(self._results, times, self.sigma, self.lag)
            out = out[self._given : self._given + count]
        self._given += count
        # Keep only what the next results' windows reach back to.
        start = self._times[self._given] if self._given < len(self._times) else self._times[-1]
        keep = int(np.searchsorted(self._times, start - _REACH * self.sigma - _TIME_TOLERANCE))
        del self._results[:keep], self._times[:keep]
        self._given -= keep
        return out
