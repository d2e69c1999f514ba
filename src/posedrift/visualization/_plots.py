"""Angle-over-time plots in the layout of the paper's Fig. 9."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, joint_angles
from posedrift.tracking import FrameResult


def _reference_angles(reference: object, n_frames: int) -> np.ndarray:
    """``(T, 8)`` degrees from a Reference, ``(T, 8)`` angles or ``(T, 15, 3)`` joints."""
    angles = getattr(reference, "angles", reference)
    angles = np.asarray(angles, dtype=float)
    if angles.ndim == 3 and angles.shape[1:] == (len(JOINT_NAMES), 3):
        angles = joint_angles(angles)
    if angles.shape != (n_frames, len(ANGLE_NAMES)):
        raise ValueError(
            f"The 'reference' of plot_angles must give {n_frames} frames of 8 angles "
            f"(a Reference, a (T, 8) array or (T, 15, 3) joints). Got shape {angles.shape}."
        )
    return angles


def plot_angles(
    results: Sequence[FrameResult],
    path: str | Path,
    *,
    reference: object | None = None,
    fps: float | None = 30.0,
    title: str | None = None,
) -> Path:
    """Plot the eight joint angles over time: eight panels, estimate against reference.

    The layout of the paper's Fig. 9: (a) left elbow, (b) right elbow, (c) left
    shoulder, (d) right shoulder, (e) left knee, (f) right knee, (g) left hip, (h)
    right hip; solid lines the estimate, dashed the reference, with the mean
    absolute error (Eq. 2) in each panel's title when a reference is given.

    Parameters
    ----------
    results : sequence of FrameResult
    path : str or Path
        An image file (``.png``, ``.pdf``, ``.svg``).
    reference : evaluation.Reference, (T, 8) degrees or (T, 15, 3) joints, optional
        One row per result.
    fps : float or None
        The horizontal axis is seconds at this rate; None plots frame numbers.
    title : str, optional

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    results = list(results)
    if not results:
        raise ValueError("plot_angles got no results.")
    estimate = np.array([r.angles for r in results])
    index = np.array([r.index for r in results], dtype=float)
    ref = None if reference is None else _reference_angles(reference, len(results))
    x = index / fps if fps else index
    fig, axes = plt.subplots(4, 2, figsize=(10, 10), sharex=True)
    fig.subplots_adjust(left=0.07, right=0.98, bottom=0.06, top=0.93, hspace=0.3, wspace=0.18)
    for k, (name, ax) in enumerate(zip(ANGLE_NAMES, axes.reshape(-1), strict=True)):
        ax.plot(x, estimate[:, k], "-", color="C0", lw=1.4, label="estimate")
        label = f"({'abcdefgh'[k]}) {name.replace('_', ' ')}"
        if ref is not None:
            ax.plot(x, ref[:, k], "--", color="C3", lw=1.4, label="reference")
            both = np.isfinite(estimate[:, k]) & np.isfinite(ref[:, k])
            if both.any():
                error = np.mean(np.abs(estimate[both, k] - ref[both, k]))
                label += f": mean |error| {error:.1f} deg"
        lost = ~np.isfinite(estimate[:, k])
        if lost.any():
            ax.plot(x[lost], np.zeros(lost.sum()), "|", color="0.5", ms=6, label="no estimate")
        ax.set_title(label, fontsize=10)
        ax.set_ylim(-5, 190)
        ax.set_yticks([0, 45, 90, 135, 180])
        ax.set_ylabel("degrees")
        ax.grid(alpha=0.3)
    for ax in axes[-1]:
        ax.set_xlabel("time (s)" if fps else "frame")
    axes[0, 0].legend(loc="lower left", fontsize=8)
    if title:
        fig.suptitle(title)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path
