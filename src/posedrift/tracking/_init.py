"""Initialization: calibration (stature, bone lengths, part reach) from one labelled frame.

The paper calibrates on a T-pose (Section 3.3.1). Real recordings start with the
arms relaxed, so any upright pose works here: the stature comes from the extent of
the body along its trunk axis, each bone length from the distance between part
boundaries where both ends are seen and plausible, and the anthropometric priors
(``skeleton.SEGMENT_RATIOS``) fill in the rest, scaled to the person. One frame's
boundaries place a limb bone only to a few centimetres, so the tracker keeps
measuring the limbs over its first frames (:class:`LimbLengths`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, PART_INDEX
from posedrift.skeleton._fit import (
    part_boundaries,
    prior_bone_lengths,
    prior_part_lengths,
    ring_joints,
    shoulder_offset_of,
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
        The world's up direction in the camera frame: from :func:`calibrate`, the
        trunk's axis (:func:`estimate_up`, which the stature is measured along); the
        tracker then replaces it by :func:`world_up` of the calibration skeleton (or
        of the floor), which tells a camera that looks down or up.
    shoulders : (2,) float or None
        Where the shoulders sit from the neck, ``(across, below)`` in metres
        (:func:`measure_shoulders`); None for the T-pose's geometry.
    """

    height: float
    bone_lengths: np.ndarray
    reach: np.ndarray
    up: np.ndarray
    shoulders: np.ndarray | None = None


# Plausible shoulder offsets from the neck, as fractions of stature: (across, below).
_SHOULDER_RANGE = ((0.07, 0.17), (-0.01, 0.06))


def measure_shoulders(joints: np.ndarray, height: float) -> np.ndarray | None:
    """The person's shoulder offset from the neck (:func:`shoulder_offset_of`) at initialization.

    Measured on a skeleton fitted without anchoring the shoulders (the arms place
    them); None where it is unknown or implausible (outside ``_SHOULDER_RANGE``).
    """
    offset = shoulder_offset_of(joints)
    for value, (low, high) in zip(offset, _SHOULDER_RANGE, strict=True):
        if not low * height <= value <= high * height:  # also False for NaN
            return None
    return offset


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
    """The body's upward direction: the trunk axis towards the head (else camera ``-Y``)."""
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


CAMERA_UP = np.array([0.0, -1.0, 0.0])
"""The world's up in the frame of a level camera (OpenCV axes: +Y down)."""
_UPRIGHT_DEG = 35.0  # a line further from the camera's vertical is not taken for the world's
_STRAIGHT_KNEE_DEG = 25.0  # a knee bent less than this is a standing leg


def world_up(joints: np.ndarray, *, floor_normal: np.ndarray | None = None) -> np.ndarray:
    """The world's up direction in the camera frame, for a camera that may look down or up.

    The floor's normal where a floor plane is known; else the line from the ankles
    of a standing skeleton (both knees straight) to its neck: a person standing when
    the tracker calibrates stands upright. Camera ``-Y`` (:data:`CAMERA_UP`) where
    the skeleton is incomplete or not standing (a seated person's trunk leans back:
    on the real recording that begins seated its pelvis-to-neck line lay 13 degrees
    behind the others' standing lines) or its line leans more than 35 degrees from
    the camera's vertical.

    The line from the ankles to the neck of the skeleton fitted to a person standing
    in front of the camera stays within 1.5 degrees of the true vertical, level or
    looking down 24 degrees; the trunk's points (:func:`estimate_up`) lean 6-8
    degrees back with the chest's surface.

    Parameters
    ----------
    joints : (15, 3) float
        A skeleton in the camera frame, metres (``JOINT_NAMES``).
    floor_normal : (3,) float, optional
        The floor plane's normal, either sign.

    Returns
    -------
    (3,) float
        Unit vector.

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> level = t_pose_joints(1.75) * [1.0, -1.0, -1.0] + [0.0, 0.0, 3.0]
    >>> np.round(world_up(level), 6).tolist()
    [0.0, -1.0, 0.0]
    >>> t = np.radians(20.0)  # the same person seen by a camera looking 20 degrees down
    >>> tilt = np.array([[1, 0, 0], [0, np.cos(t), -np.sin(t)], [0, np.sin(t), np.cos(t)]])
    >>> np.round(world_up(level @ tilt.T), 6).tolist() == np.round(tilt @ [0, -1, 0], 6).tolist()
    True
    """
    if floor_normal is not None:
        normal = np.asarray(floor_normal, dtype=float)
        normal = normal / np.linalg.norm(normal)
        return normal if normal @ CAMERA_UP >= 0 else -normal
    joints = np.asarray(joints, dtype=float)
    if not np.isfinite(joints).all():
        return CAMERA_UP.copy()
    standing = all(
        _bend(joints[_J[f"{side}_hip"]], joints[_J[f"{side}_knee"]], joints[_J[f"{side}_foot"]])
        < _STRAIGHT_KNEE_DEG
        for side in ("right", "left")
    )
    if not standing:
        return CAMERA_UP.copy()
    line = joints[_J["neck"]] - 0.5 * (joints[_J["right_foot"]] + joints[_J["left_foot"]])
    line = line / max(np.linalg.norm(line), 1e-12)
    return line if line @ CAMERA_UP >= np.cos(np.radians(_UPRIGHT_DEG)) else CAMERA_UP.copy()


def _bend(hip: np.ndarray, knee: np.ndarray, foot: np.ndarray) -> float:
    """Degrees a leg bends at its knee (0: straight)."""
    thigh, shank = knee - hip, foot - knee
    cos = thigh @ shank / max(np.linalg.norm(thigh) * np.linalg.norm(shank), 1e-12)
    return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))))


def level_rotation(up: np.ndarray) -> np.ndarray:
    """The rotation ``R`` taking a level camera's frame to this one's: ``R @ CAMERA_UP == up``.

    The smallest such rotation (about ``CAMERA_UP x up``): a camera tilted down or
    rolled, not turned. Row vectors in this camera's frame map to the level frame as
    ``points @ R``.

    Examples
    --------
    >>> t = np.radians(24.0)
    >>> up = np.array([0.0, -np.cos(t), -np.sin(t)])  # a camera looking 24 degrees down
    >>> bool(np.allclose(level_rotation(up) @ CAMERA_UP, up))
    True
    >>> bool(np.allclose(level_rotation(CAMERA_UP), np.eye(3)))
    True
    """
    up = np.asarray(up, dtype=float)
    up = up / np.linalg.norm(up)
    axis = np.cross(CAMERA_UP, up)
    sin, cos = float(np.linalg.norm(axis)), float(CAMERA_UP @ up)
    if sin < 1e-12:
        return np.eye(3) if cos > 0 else np.diag([1.0, -1.0, -1.0])
    k = axis / sin
    cross = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + sin * cross + (1.0 - cos) * (cross @ cross)


# Limb bones measured between ring joints at calibration: child joint -> parent joint.
_LIMB_PARENTS = {
    "hand": "elbow",  # forearm
    "foot": "knee",  # shank
    "knee": "hip",  # thigh
    "elbow": "shoulder",  # upper arm
}


def _limb_ratios(centres, counts, height: float) -> dict[str, float]:
    """Measured over expected length of each limb bone seen at both ends.

    Left and right averaged; ratios outside [0.65, 1.4] (a misplaced boundary) dropped.
    """
    bones = prior_bone_lengths(height)
    ring = {name: value[0] for name, value in ring_joints(centres, counts, height=height).items()}
    ratios = {}
    for child, parent in _LIMB_PARENTS.items():
        found = []
        for side in ("right", "left"):
            a, b = f"{side}_{child}", f"{side}_{parent}"
            if a in ring and b in ring:
                ratio = float(np.linalg.norm(ring[a] - ring[b])) / bones[_J[a]]
                if 0.65 <= ratio <= 1.4:
                    found.append(ratio)
        if found:
            ratios[child] = float(np.mean(found))
    return ratios


def calibrate(
    points: np.ndarray,
    labels: np.ndarray,
    edges: tuple[np.ndarray, np.ndarray],
    *,
    full_points: np.ndarray | None = None,
    height: float | None = None,
    truncated: bool = False,
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
    truncated : bool
        The person runs off the top or the bottom of the image (too near the camera):
        their extent then only bounds the stature from below, and the stature is
        scaled up until the limb bones measured between part boundaries agree with
        it (the segment ratios of a body that tall).

    Returns
    -------
    Calibration
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels).astype(np.int64)
    up = estimate_up(points, labels)
    measure = height is None
    rows, cols = edges
    centres, counts = part_boundaries(points, labels, rows, cols)
    if height is None:
        cloud = points if full_points is None else np.asarray(full_points, dtype=float)
        proj = cloud @ up
        # Robust extent: the top and bottom 0.2 percent are trimmed, plus the sole and
        # scalp that a frontal view cannot see.
        lo, hi = np.percentile(proj, [0.2, 99.8])
        height = float(np.clip(hi - lo + 0.02, 0.9, 2.3))
    ratios = _limb_ratios(centres, counts, height)
    for _ in range(4 if measure and truncated else 0):
        # A cut-off silhouette is shorter than the person: grow the stature by the
        # limbs' measured-to-expected length until they agree (never shrink it).
        scale = float(np.median(list(ratios.values()))) if ratios else 1.0
        if scale < 1.02 or height >= 2.3:
            break
        height = float(min(height * scale, 2.3))
        ratios = _limb_ratios(centres, counts, height)
    bones = bone_lengths_from_ratios(height, ratios)
    reach = prior_reach(height)
    return Calibration(height=height, bone_lengths=bones, reach=reach, up=up)


def bone_lengths_from_ratios(height: float, ratios: Mapping[str, float]) -> np.ndarray:
    """Bone lengths ``(15,)``: the priors for ``height``, limb bones scaled by ``ratios``.

    ``ratios`` maps a limb bone's child joint kind (``"hand"``, ``"foot"``,
    ``"knee"``, ``"elbow"``) to its measured over expected length; a limb bone
    measured on neither side takes the prior scaled like the others.
    """
    bones = prior_bone_lengths(height)
    scale = float(np.median(list(ratios.values()))) if ratios else 1.0
    for child in _LIMB_PARENTS:
        for side in ("right", "left"):
            bones[_J[f"{side}_{child}"]] *= ratios.get(child, scale)
    return bones


class LimbLengths:
    """Limb bone lengths measured over several frames: the median of each bone's ratios.

    The first frame alone places each ring joint (a part boundary) to a few
    centimetres: over the first second of the development clips one frame's
    upper-arm, thigh and shank lengths spread by 2-5 cm. :meth:`add` measures
    the limbs of one more labelled frame; :meth:`refine` gives the calibration
    with each limb bone at the median of what was measured so far (stature and
    everything else unchanged).

    Parameters
    ----------
    frames : int
        How many frames to measure; later calls of :meth:`add` are ignored.
    """

    def __init__(self, frames: int) -> None:
        self.frames = int(frames)
        self.seen = 0
        self._ratios: dict[str, list[float]] = {child: [] for child in _LIMB_PARENTS}

    @property
    def done(self) -> bool:
        """Whether ``frames`` frames have been measured."""
        return self.seen >= self.frames

    def add(
        self,
        points: np.ndarray,
        labels: np.ndarray,
        edges: tuple[np.ndarray, np.ndarray],
        height: float,
    ) -> None:
        """Measure the limb bones seen at both ends in one labelled frame."""
        if self.done:
            return
        self.seen += 1
        centres, counts = part_boundaries(points, labels, *edges)
        for child, ratio in _limb_ratios(centres, counts, height).items():
            self._ratios[child].append(ratio)

    def refine(self, calibration: Calibration) -> Calibration:
        """``calibration`` with its limb bones at the median of the measured ratios."""
        ratios = {c: float(np.median(r)) for c, r in self._ratios.items() if r}
        if not ratios:
            return calibration
        bones = bone_lengths_from_ratios(calibration.height, ratios)
        return replace(calibration, bone_lengths=bones)


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
    # The default (balanced) tree on purpose: pixels on a grid are often equidistant, and
    # another tree layout breaks those ties differently (other voters, other labels).
    _, idx = cKDTree(pixel_points[known]).query(points, k=kk)
    idx = np.asarray(idx).reshape(len(points), kk)
    votes = pixel_labels[known][idx]
    return np.argmax(
        _vote_counts(np.repeat(np.arange(len(points)), kk), votes.ravel(), len(points)), axis=1
    ).astype(np.int64)


def _vote_counts(
    voters: np.ndarray, parts: np.ndarray, n: int, weights: np.ndarray | None = None
) -> np.ndarray:
    """Votes ``(n, 15)`` for each part: ``np.add.at(counts, (voters, parts), weights)``, faster.

    The votes are small integers (or halves), added exactly in any order.
    """
    if len(parts) and (parts.min() < 0 or parts.max() >= 15):
        raise IndexError(f"part labels must lie in [0, 15), got {parts.min()}..{parts.max()}")
    flat = np.bincount(voters * 15 + parts, weights=weights, minlength=n * 15)
    return flat.astype(float, copy=False).reshape(n, 15)


def smooth_labels(labels: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_iter: int = 2):
    """Majority vote of each point and its graph neighbours (removes isolated labels)."""
    labels = np.asarray(labels).astype(np.int64).copy()
    n = len(labels)
    for _ in range(n_iter):
        # Votes: 1.5 for the point's own label, 1 for each neighbour's (counted once per
        # direction of each edge).
        ok = labels >= 0
        voters = np.concatenate([np.flatnonzero(ok), rows, cols])
        parts = np.concatenate([labels[ok], labels[cols], labels[rows]])
        weights = np.concatenate([np.full(int(ok.sum()), 1.5), np.ones(2 * len(rows))])
        good = parts >= 0
        counts = _vote_counts(voters[good], parts[good], n, weights[good])
        has = counts.sum(axis=1) > 0
        labels[has] = np.argmax(counts[has], axis=1)
    return labels


REACH_QUANTILE = 95.0
REACH_MARGIN = 0.05


def measure_reach(
    graph,
    points: np.ndarray,
    labels: np.ndarray,
    anchors: np.ndarray,
    *,
    height: float,
    quantile: float = REACH_QUANTILE,
    margin: float = REACH_MARGIN,
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


def _segment_distances(points: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> np.ndarray:
    """Distance ``(N, S)`` from each point to each segment."""
    ab = ends - starts
    denom = np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-12)
    t = np.einsum("nsj,sj->ns", points[:, None, :] - starts[None], ab) / denom
    closest = starts[None] + np.clip(t, 0.0, 1.0)[..., None] * ab[None]
    return np.linalg.norm(points[:, None, :] - closest, axis=2)


# Body radius of each part as a fraction of stature (for labelling by nearest bone).
_PART_RADIUS = np.array(
    [0.06, 0.095, 0.095, 0.03, 0.03, 0.025, 0.025, 0.02, 0.02, 0.05, 0.05, 0.035, 0.035, 0.02, 0.02]
)


def geometric_labels(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body-part labels of an upright person facing the camera, without a forest.

    A skeleton is laid over the points from anthropometric ratios
    (``skeleton.SEGMENT_RATIOS``): stature from the vertical extent, trunk at the
    median of the trunk band, each arm along the principal direction of the points
    beside the trunk on its side (hanging, raised or in a T-pose: elbows taken as
    straight), legs straight down to the lowest points; each point then takes the
    part of the nearest bone (distance less the part's radius).

    Parameters
    ----------
    points : (N, 3) float
        Camera-frame points of the person (metres), upright, facing the camera.

    Returns
    -------
    labels : (N,) int
    joints : (15, 3) float
        The skeleton used.
    """
    from posedrift.skeleton._definitions import SEGMENT_RATIOS
    from posedrift.skeleton._fit import bone_anchors

    points = np.asarray(points, dtype=float)
    up = np.array([0.0, -1.0, 0.0])
    c = points - points.mean(axis=0)
    _, v = np.linalg.eigh(c.T @ c)
    axis = v[:, 2] if v[:, 2] @ up >= 0 else -v[:, 2]
    if axis @ up > np.cos(np.radians(30)):
        up = axis
    h = (points - points.mean(axis=0)) @ up
    floor = np.percentile(h, 0.5)
    height = float(np.clip(np.percentile(h, 99.5) - floor + 0.02, 0.9, 2.3))
    h = h - floor
    forward = np.array([0.0, 0.0, -1.0])  # the person faces the camera
    right = np.cross(forward, up)  # the person's right, in the camera frame
    right /= np.linalg.norm(right)
    forward = np.cross(right, up)
    r = SEGMENT_RATIOS
    trunk = (h > r["hip_height"] * height) & (h < r["shoulder_height"] * height)
    base = points.mean(axis=0) if not trunk.any() else np.median(points[trunk], axis=0)
    lateral = (points - base) @ right
    centre = base - ((base - points.mean(axis=0)) @ up) * up
    depth = float(np.median(((points[trunk] if trunk.any() else points) - base) @ forward))

    def at(height_frac: float, side: float, ahead: float = 0.0) -> np.ndarray:
        return (
            centre
            + (floor + height_frac * height - (centre - points.mean(axis=0)) @ up) * up
            + side * right
            + (depth - ahead) * forward
        )

    # Joints sit about a limb radius behind the visible surface.
    j = np.zeros((15, 3))
    sh_h, hip_h = r["shoulder_height"], r["hip_height"]
    half_sh, half_hip = 0.5 * r["shoulder_width"] * height, 0.5 * r["hip_width"] * height
    j[_J["neck"]] = at(sh_h + 0.02, 0.0, 0.06)
    j[_J["head"]] = at(1.0 - 0.5 * r["head_height"], 0.0, 0.07)
    pelvis_h = hip_h
    j[_J["torso"]] = at(0.5 * (sh_h + 0.02 + pelvis_h), 0.0, 0.08)
    for sign, side in ((1.0, "right"), (-1.0, "left")):
        shoulder = at(sh_h, sign * half_sh, 0.05)
        # Each leg follows the points on its side of the body's midline.
        leg = (sign * lateral > 0) & (h < hip_h * height)
        knee_h, ankle_h = hip_h - r["thigh"], r["ankle_height"] + 0.03
        offsets = []
        for band_h in (knee_h, ankle_h):
            band = leg & (np.abs(h - band_h * height) < 0.04 * height)
            offsets.append(float(np.median(lateral[band])) if band.sum() >= 3 else sign * half_hip)
        hip = at(hip_h, sign * half_hip, 0.07)
        knee = at(knee_h, offsets[0], 0.05)
        ankle = at(ankle_h - 0.03, offsets[1], 0.04)
        j[_J[f"{side}_shoulder"]], j[_J[f"{side}_hip"]] = shoulder, hip
        j[_J[f"{side}_knee"]], j[_J[f"{side}_foot"]] = knee, ankle
        # The arm: points beside the trunk on this side, above the hips.
        arm = (sign * lateral > half_sh * 0.85) & (h > hip_h * height * 0.8)
        direction = -up
        if arm.sum() >= 8:
            a = points[arm] - shoulder
            cov = a.T @ a
            _, vv = np.linalg.eigh(cov)
            d = vv[:, 2]
            mean_dir = a.mean(axis=0)
            d = d if d @ mean_dir >= 0 else -d
            if np.linalg.norm(mean_dir) > 0.1 * height:
                direction = d
        elbow = shoulder + r["upper_arm"] * height * direction
        wrist = elbow + r["forearm"] * height * direction
        j[_J[f"{side}_elbow"]], j[_J[f"{side}_hand"]] = elbow, wrist
    bones = np.zeros(15)
    bones[_J["right_hand"]] = bones[_J["left_hand"]] = r["forearm"] * height
    bones[_J["right_foot"]] = bones[_J["left_foot"]] = r["shank"] * height
    anchors = bone_anchors(j, bones, n=2)
    starts, ends = anchors[:, 0], anchors[:, -1]
    # Stretch the sampled anchors back to the full bones.
    mid, half = 0.5 * (starts + ends), 0.5 * (ends - starts) * 2.0
    dist = _segment_distances(points, mid - half, mid + half) - _PART_RADIUS * height
    return np.argmin(dist, axis=1).astype(np.int64), j
