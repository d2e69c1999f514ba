"""Pieces the per-frame baselines share: forest labels in 3-D, pixel-grid edges, stature."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics


@dataclass(frozen=True)
class LabelledPixels:
    """One frame's person pixels in 3-D with the forest's part probabilities.

    Attributes
    ----------
    points : (N, 3) float
        Camera frame, metres.
    pixels : (N, 2) int
        ``(row, column)``.
    probabilities : (N, 15) float
        ``P(part | pixel)``.
    labels : (N,) int
        Most probable part, -1 where its probability is below the threshold.
    edges : (rows (E,), cols (E,))
        Index pairs of 4-neighbour pixels closer than ``max_step`` in depth.
    """

    points: np.ndarray
    pixels: np.ndarray
    probabilities: np.ndarray
    labels: np.ndarray
    edges: tuple[np.ndarray, np.ndarray]


def resolve_forest(forest: Any) -> Any:
    """The given forest, or the default model (loaded once per call site)."""
    if forest is not None:
        return forest
    from posedrift.labelling import BodyPartForest

    return BodyPartForest.load_default()


def grid_edges(
    pixels: np.ndarray, depth: np.ndarray, *, max_step: float = 0.05
) -> tuple[np.ndarray, np.ndarray]:
    """4-neighbour pairs among ``pixels`` whose depths differ by less than ``max_step`` metres.

    Examples
    --------
    >>> import numpy as np
    >>> depth = np.ones((2, 3), np.float32)
    >>> px = np.array([[0, 0], [0, 1], [1, 1]])
    >>> [e.tolist() for e in grid_edges(px, depth)]
    [[0, 1], [1, 2]]
    """
    h, w = depth.shape
    index = np.full((h, w), -1, dtype=np.int64)
    index[pixels[:, 0], pixels[:, 1]] = np.arange(len(pixels))
    rows, cols = [], []
    for dr, dc in ((0, 1), (1, 0)):
        a = index[: h - dr, : w - dc]
        b = index[dr:, dc:]
        za = depth[: h - dr, : w - dc]
        zb = depth[dr:, dc:]
        ok = (a >= 0) & (b >= 0) & (np.abs(za - zb) < max_step)
        rows.append(a[ok])
        cols.append(b[ok])
    return np.concatenate(rows), np.concatenate(cols)


def label_frame(
    frame: DepthFrame,
    forest: Any,
    *,
    threshold: float = 0.14,
    max_step: float = 0.05,
    segment_options: dict | None = None,
) -> LabelledPixels | None:
    """Segment the person, label its pixels with the forest, back-project them.

    Returns
    -------
    LabelledPixels or None
        None when no person is found.
    """
    from posedrift.points import segment_person

    mask = segment_person(frame, **(segment_options or {}))
    if not mask.any():
        return None
    pred = forest.predict(frame.depth, mask, frame.intrinsics)
    pixels = np.asarray(pred.pixels, dtype=np.int64)
    if len(pixels) == 0:
        return None
    depth = frame.depth
    points = _points_at(depth, pixels, frame.intrinsics)
    probabilities = np.asarray(pred.probabilities, dtype=float)
    labels = np.argmax(probabilities, axis=1)
    labels = np.where(probabilities[np.arange(len(labels)), labels] >= threshold, labels, -1)
    return LabelledPixels(
        points=points,
        pixels=pixels,
        probabilities=probabilities,
        labels=labels,
        edges=grid_edges(pixels, depth, max_step=max_step),
    )


def _points_at(depth: np.ndarray, pixels: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    z = depth[pixels[:, 0], pixels[:, 1]].astype(float)
    x = (pixels[:, 1] - intrinsics.cx) * z / intrinsics.fx
    y = (pixels[:, 0] - intrinsics.cy) * z / intrinsics.fy
    return np.column_stack([x, y, z])


def estimate_stature(points: np.ndarray) -> float:
    """Stature (metres) of an upright person facing the camera from their points.

    The vertical (image Y) extent between the 0.2 and 99.8 percentiles, plus 1 %
    for the trimmed tails. Used once, on the first frame with a person (a T-pose
    in the synthetic protocol, a relaxed standing pose on UTD-MHAD).
    """
    y = points[:, 1]
    return float(1.01 * (np.percentile(y, 99.8) - np.percentile(y, 0.2)))


def calibrate_bones(lab: LabelledPixels, image_rows: int | None = None) -> tuple[float, np.ndarray]:
    """Stature and bone lengths from one labelled frame, as the tracker calibrates them.

    :func:`posedrift.tracking._init.calibrate` on the frame's labelled pixels (the
    same measurement the tracker makes on its first frame), so that every method
    uses the same skeleton; ``image_rows`` (the frame's height in pixels) tells it
    whether the person runs off the image's top or bottom. Falls back on
    :func:`estimate_stature` and the prior ratios where it cannot run.

    Returns
    -------
    stature : float
        Metres.
    bone_lengths : (15,) float
        ``|joint - parent|`` in metres (``JOINT_PARENTS``).
    """
    from posedrift.skeleton._fit import prior_bone_lengths

    labelled = lab.labels >= 0
    try:
        from posedrift.tracking._init import calibrate

        keep = np.nonzero(labelled)[0]
        remap = np.full(len(lab.labels), -1, dtype=np.int64)
        remap[keep] = np.arange(len(keep))
        rows, cols = remap[lab.edges[0]], remap[lab.edges[1]]
        ok = (rows >= 0) & (cols >= 0)
        truncated = image_rows is not None and bool(
            np.any(lab.pixels[:, 0] == 0) or np.any(lab.pixels[:, 0] == image_rows - 1)
        )
        cal = calibrate(
            lab.points[keep],
            lab.labels[keep],
            (rows[ok], cols[ok]),
            full_points=lab.points,
            truncated=truncated,
        )
        return float(cal.height), np.asarray(cal.bone_lengths, dtype=float)
    except (ImportError, ValueError, IndexError):
        height = estimate_stature(lab.points)
        return height, prior_bone_lengths(height)


__all__ = [
    "LabelledPixels",
    "calibrate_bones",
    "estimate_stature",
    "grid_edges",
    "label_frame",
    "resolve_forest",
]
