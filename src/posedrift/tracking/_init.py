"""Initialization: calibration (stature, bone lengths, part reach) from one labelled frame.

The paper calibrates on a T-pose (Section 3.3.1). Real recordings start with the
arms relaxed, so any upright pose works here: the stature comes from the extent of
the body along its trunk axis, each bone length from the distance between part
boundaries where both ends are seen and plausible, and the anthropometric priors
(``skeleton.SEGMENT_RATIOS``) fill in the rest, scaled to the person.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, PART_INDEX
from posedrift.skeleton._fit import (
    part_boundaries,
    prior_bone_lengths,
    prior_part_lengths,
    ring_joints,
)

_J = JOINT_INDEX
_P = PART_INDEX


@dataclass(frozen=True)
class Calibration:
    """A person's measurements, fixed at initialization.

    Attributes
    ----------
    height : float
        Stature H in metres.
    bone_lengths : (15,) float
        ``|joint_i - joint_parent(i)|`` in metres (``JOINT_PARENTS``).
    reach : (15,) float
        ``D_j`` of Algorithm 2: geodesic reach of each part from its anchor, as a
        fraction of H.
    up : (3,) float
        The person's upward direction in the camera frame at initialization.
    """

    height: float
    bone_lengths: np.ndarray
    reach: np.ndarray
    up: np.ndarray


def prior_reach(height: float) -> np.ndarray:
    """Geodesic reach of each part from its middle, as a fraction of stature (priors)."""
    lengths = prior_part_lengths(height) / height
    reach = 0.5 * lengths + 0.045
    reach[_P["upper_torso"]] = 0.17
    reach[_P["lower_torso"]] = 0.16
    reach[_P["head"]] = 0.5 * lengths[_P["head"]] + 0.04
    reach[[_P["right_hand"], _P["left_hand"]]] += 0.02
    reach[[_P["right_foot"], _P["left_foot"]]] += 0.04
    return reach


def estimate_up(points: np.ndarray, labels: np.ndarray) -> np.ndarray:
    """The body's upward direction: trunk axis oriented towards the head (camera ``-Y`` fallback)."""
    up = np.array([0.0, -1.0, 0.0])
    torso = np.isin(labels, [_P["upper_torso"], _P["lower_torso"]])
    head = labels == _P["head"]
    if torso.sum() >= 10:
        c = points[torso] - points[torso].mean(axis=0)
        _, v = np.linalg.eigh(c.T @ c)
        axis = v[:, 2]
        ref = points[head].mean(axis=0) - points[torso].mean(axis=0) if head.any() else up
        axis = axis if axis @ ref >= 0 else -axis
        # Trust the trunk axis only near the camera's vertical (an upright person).
        if axis @ up > np.cos(np.radians(40)):
            up = axis
    return up / np.linalg.norm(up)


def calibrate(
    points: np.ndarray,
    labels: np.ndarray,
    edges: tuple[np.ndarray, np.ndarray],
    *,
    full_points: np.ndarray | None = None,
    height: float | None = None,
) -> Calibration:
    """Measure stature, bone lengths and part reach from one labelled upright frame.

    Parameters
    ----------
    points : (N, 3) float
        Downsampled person points, metres.
    labels : (N,) int
        Their parts.
    edges : (rows, cols)
        Neighbour pairs on ``points``.
    full_points : (M, 3) float, optional
        All the person's points (a better extent for the stature).
    height : float, optional
        A known stature (metres), which then is not measured.

    Returns
    -------
    Calibration
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels).astype(np.int64)
    up = estimate_up(points, labels)
    if height is None:
        cloud = points if full_points is None else np.asarray(full_points, dtype=float)
        proj = cloud @ up
        # Robust extent: the top and bottom 0.2 percent are trimmed, plus the sole and
        # scalp that a frontal view cannot see.
        lo, hi = np.percentile(proj, [0.2, 99.8])
        height = float(np.clip(hi - lo + 0.02, 0.9, 2.3))
    bones = prior_bone_lengths(height)
    rows, cols = edges
    centres, counts = part_boundaries(points, labels, rows, cols)
    ring = {name: value[0] for name, value in ring_joints(centres, counts, height=height).items()}
    # Limb bones measured between ring joints where both ends are seen; left and right
    # averaged; a bone measured on neither side takes the prior scaled like the others.
    pairs = {
        "hand": "elbow",  # forearm
        "foot": "knee",  # shank
        "knee": "hip",  # thigh
        "elbow": "shoulder",  # upper arm
    }
    ratios = {}
    for child, parent in pairs.items():
        found = []
        for side in ("right", "left"):
            a, b = f"{side}_{child}", f"{side}_{parent}"
            if a in ring and b in ring:
                ratio = float(np.linalg.norm(ring[a] - ring[b])) / bones[_J[a]]
                if 0.65 <= ratio <= 1.4:
                    found.append(ratio)
        if found:
            ratios[child] = float(np.mean(found))
    scale = float(np.median(list(ratios.values()))) if ratios else 1.0
    for child in pairs:
        for side in ("right", "left"):
            bones[_J[f"{side}_{child}"]] *= ratios.get(child, scale)
    reach = prior_reach(height)
    return Calibration(height=height, bone_lengths=bones, reach=reach, up=up)


def label_template_points(
    points: np.ndarray, pixel_points: np.ndarray, pixel_labels: np.ndarray, *, k: int = 5
) -> np.ndarray:
    """Labels of downsampled points by a vote of their nearest labelled pixels.

    Parameters
    ----------
    points : (N, 3) float
        Downsampled points.
    pixel_points : (M, 3) float
        The person's full-resolution points.
    pixel_labels : (M,) int
        Their labels (-1 unknown).

    Returns
    -------
    labels : (N,) int
        -1 where no labelled pixel is near.
    """
    from scipy.spatial import cKDTree

    known = pixel_labels >= 0
    if not known.any():
        return np.full(len(points), -1, dtype=np.int64)
    kk = min(k, int(known.sum()))
    _, idx = cKDTree(pixel_points[known]).query(points, k=kk)
    idx = np.asarray(idx).reshape(len(points), kk)
    votes = pixel_labels[known][idx]
    counts = np.zeros((len(points), 15))
    np.add.at(counts, (np.repeat(np.arange(len(points)), kk), votes.ravel()), 1.0)
    return np.argmax(counts, axis=1).astype(np.int64)


def smooth_labels(labels: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_iter: int = 2):
    """Majority vote of each point and its graph neighbours (removes isolated labels)."""
    labels = np.asarray(labels).astype(np.int64).copy()
    n = len(labels)
    for _ in range(n_iter):
        counts = np.zeros((n, 15))
        ok = labels >= 0
        counts[np.nonzero(ok)[0], labels[ok]] += 1.5
        for a, b in ((rows, cols), (cols, rows)):
            good = labels[b] >= 0
            np.add.at(counts, (a[good], labels[b][good]), 1.0)
        has = counts.sum(axis=1) > 0
        labels[has] = np.argmax(counts[has], axis=1)
    return labels



def measure_reach(
    graph,
    points: np.ndarray,
    labels: np.ndarray,
    anchors: np.ndarray,
    *,
    height: float,
    quantile: float = 90.0,
    margin: float = 0.03,
    min_points: int = 5,
) -> np.ndarray:
    """``D_j`` of Algorithm 2 measured on a labelled frame, as a fraction of stature.

    The ``quantile`` of the geodesic distances from each part's anchor to the part's
    own points, plus ``margin`` metres; clipped to [0.7, 2] times the prior
    (:func:`prior_reach`), which also stands in for parts with too few points.
    """
    from posedrift.labelling._relabel import geodesic_distances

    prior = prior_reach(height)
    geo = geodesic_distances(graph, points, anchors, labels)
    out = prior.copy()
    for j in range(len(prior)):
        own = geo[j, labels == j]
        own = own[np.isfinite(own)]
        if len(own) >= min_points:
            value = (np.percentile(own, quantile) + margin) / height
            out[j] = float(np.clip(value, 0.7 * prior[j], 2.0 * prior[j]))
    return out
