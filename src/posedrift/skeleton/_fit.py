"""The skeleton from labelled points: part boundaries, part axes and calibrated bone lengths.

Section 3.4 of the paper: joint proposals from the labelled parts, then a skeleton
with the length constraints measured at initialization. Here:

- *ring* joints (neck, elbows, wrists, knees, ankles) sit at the boundary between
  two adjacent parts: the mean of the midpoints of the graph edges joining them,
  pushed back along the camera ray by the limb's radius (only the front surface is
  seen);
- the proximal limb joints (shoulders, hips) and the distal ends (hands, feet)
  follow from a ring joint, the part's axis (principal direction of its points,
  oriented towards its mean-shift mode) and the calibrated bone length, so every
  limb bone has exactly its calibrated length;
- ``torso`` is the midpoint of ``neck`` and the pelvis centre (METHOD section 2).

Where a part or a boundary has too little support, the predicted joint (the
previous skeleton moved by the registration's warp) stands in, with a lower
confidence.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, JOINT_PARENTS, PART_INDEX, SEGMENT_RATIOS

_J = JOINT_INDEX
_P = PART_INDEX
N_PARTS = 15

# Ring joints: joint -> (part a, part b, push-back radius in metres).
RING_JOINTS: dict[str, tuple[str, str, float]] = {
    "neck": ("head", "upper_torso", 0.05),
    "right_elbow": ("right_upper_arm", "right_forearm", 0.035),
    "left_elbow": ("left_upper_arm", "left_forearm", 0.035),
    "right_hand": ("right_forearm", "right_hand", 0.025),
    "left_hand": ("left_forearm", "left_hand", 0.025),
    "right_knee": ("right_thigh", "right_shank", 0.02),
    "left_knee": ("left_thigh", "left_shank", 0.02),
    "right_foot": ("right_shank", "right_foot", 0.03),
    "left_foot": ("left_shank", "left_foot", 0.03),
    "right_shoulder": ("upper_torso", "right_upper_arm", 0.05),
    "left_shoulder": ("upper_torso", "left_upper_arm", 0.05),
    "right_hip": ("lower_torso", "right_thigh", 0.095),
    "left_hip": ("lower_torso", "left_thigh", 0.095),
}

# Radius (metres) by which a part's visible surface lies in front of its axis.
PART_RADII = np.array(
    [0.07, 0.09, 0.09, 0.035, 0.035, 0.03, 0.03, 0.02, 0.02, 0.06, 0.06, 0.045, 0.045, 0.03, 0.03]
)

# Limb chains: (anchor ring joint, part whose axis is followed, joint placed).
_LIMBS: tuple[tuple[str, str, str], ...] = (
    ("right_elbow", "right_upper_arm", "right_shoulder"),
    ("left_elbow", "left_upper_arm", "left_shoulder"),
    ("right_elbow", "right_forearm", "right_hand"),
    ("left_elbow", "left_forearm", "left_hand"),
    ("right_knee", "right_thigh", "right_hip"),
    ("left_knee", "left_thigh", "left_hip"),
    ("right_knee", "right_shank", "right_foot"),
    ("left_knee", "left_shank", "left_foot"),
)


def prior_bone_lengths(height: float) -> np.ndarray:
    """Bone lengths ``(15,)`` (joint to its parent in ``JOINT_PARENTS``) from SEGMENT_RATIOS.

    ``lengths[i] = |joint_i - joint_parent(i)|``; 0 for the root (torso).
    """
    from posedrift.skeleton._tpose import t_pose_joints

    joints = t_pose_joints(height)
    out = np.zeros(len(JOINT_PARENTS))
    for i, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            out[i] = np.linalg.norm(joints[i] - joints[p])
    return out


def prior_part_lengths(height: float) -> np.ndarray:
    """Length of each of the 15 parts (metres) from SEGMENT_RATIOS."""
    r = SEGMENT_RATIOS
    h = float(height)
    neck_y = (r["shoulder_height"] + 0.02) * h
    return h * np.array(
        [
            r["head_height"],
            0.5 * (neck_y / h - r["hip_height"]),
            0.5 * (neck_y / h - r["hip_height"]),
            r["upper_arm"],
            r["upper_arm"],
            r["forearm"],
            r["forearm"],
            r["hand"],
            r["hand"],
            r["thigh"],
            r["thigh"],
            r["shank"],
            r["shank"],
            r["foot_length"],
            r["foot_length"],
        ]
    )


@dataclass(frozen=True)
class SkeletonFit:
    """A fitted skeleton.

    Attributes
    ----------
    joints : (15, 3) float
        Metres, camera frame; NaN where unknown.
    confidence : (15,) float
        In [0, 1].
    measured : (15,) bool
        Whether each joint came from this frame's labels (not the prediction).
    length_ratio : (15,) float
        For ring joints with a measured ring parent/child pair: measured distance
        over calibrated length (1 is perfect); NaN elsewhere.
    """

    joints: np.ndarray
    confidence: np.ndarray
    measured: np.ndarray
    length_ratio: np.ndarray


def part_boundaries(
    points: np.ndarray, labels: np.ndarray, rows: np.ndarray, cols: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Centroid of the edge midpoints between every pair of parts.

    Returns
    -------
    centres : (15, 15, 3) float
        Symmetric; NaN where two parts do not touch.
    counts : (15, 15) int
        Edges joining each pair.
    """
    la, lb = labels[rows], labels[cols]
    ok = (la != lb) & (la >= 0) & (lb >= 0) & (la < N_PARTS) & (lb < N_PARTS)
    a, b = np.minimum(la[ok], lb[ok]), np.maximum(la[ok], lb[ok])
    code = a * N_PARTS + b
    mid = 0.5 * (points[rows[ok]] + points[cols[ok]])
    counts = np.bincount(code, minlength=N_PARTS * N_PARTS)
    centres = np.full((N_PARTS * N_PARTS, 3), np.nan)
    have = counts > 0
    for d in range(3):
        centres[have, d] = (
            np.bincount(code, weights=mid[:, d], minlength=N_PARTS * N_PARTS)[have] / counts[have]
        )
    centres = centres.reshape(N_PARTS, N_PARTS, 3)
    counts = counts.reshape(N_PARTS, N_PARTS)
    upper = np.triu_indices(N_PARTS, 1)
    centres[upper[1], upper[0]] = centres[upper]
    counts = counts + counts.T
    return centres, counts


def part_axes(
    points: np.ndarray, labels: np.ndarray, *, min_points: int = 5
) -> tuple[np.ndarray, np.ndarray]:
    """Principal direction of each part's points and its elongation (lambda1 / lambda2).

    Returns
    -------
    axes : (15, 3) float
        Unit vectors (sign arbitrary); NaN for parts with too few points.
    elongation : (15,) float
        0 for parts with too few points.
    """
    axes = np.full((N_PARTS, 3), np.nan)
    elong = np.zeros(N_PARTS)
    ok = (labels >= 0) & (labels < N_PARTS)
    lab, p = labels[ok], points[ok]
    counts = np.bincount(lab, minlength=N_PARTS)
    means = np.zeros((N_PARTS, 3))
    for d in range(3):
        means[:, d] = np.bincount(lab, weights=p[:, d], minlength=N_PARTS) / np.maximum(counts, 1)
    c = p - means[lab]
    cov = np.zeros((N_PARTS, 3, 3))
    for i in range(3):
        for j in range(i, 3):
            cov[:, i, j] = np.bincount(lab, weights=c[:, i] * c[:, j], minlength=N_PARTS)
            cov[:, j, i] = cov[:, i, j]
    good = counts >= min_points
    if good.any():
        w, v = np.linalg.eigh(cov[good])
        axes[good] = v[:, :, 2]
        elong[good] = w[:, 2] / np.maximum(w[:, 1], 1e-12)
    return axes, elong


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else np.full(3, np.nan)


def _push(p: np.ndarray, radius: float) -> np.ndarray:
    """Move a surface point back along its camera ray by ``radius``."""
    return p + radius * _unit(p)


# How each limb bone's direction is measured: weights of the part's principal axis and
# of the direction between the two (corrected) ring joints at its ends.
LIMB_DIRECTION_WEIGHTS: dict[str, tuple[float, float]] = {
    "upper_arm": (1.0, 1.0),
    "forearm": (1.0, 1.0),
    "thigh": (0.3, 1.0),
    "shank": (1.0, 0.5),
}


def ring_joints(
    centres: np.ndarray, counts: np.ndarray, *, height: float, min_edges: int = 2
) -> dict[str, tuple[np.ndarray, float]]:
    """Joint estimates from part boundaries, corrected for where the boundaries lie.

    Boundaries lie on the visible surface: each is pushed back along its camera ray
    by the limb's radius. The thigh/shank boundary sits below the knee, the
    torso/thigh boundary below and inside the hip, the torso/upper-arm boundary
    below the shoulder: fixed offsets (scaled by stature) move them onto the joints.

    Returns
    -------
    dict
        ``joint name -> (position (3,), support in [0, 1])`` for the boundaries seen.
    """
    scale = height / 1.75
    raw = {}
    for name, (pa, pb, radius) in RING_JOINTS.items():
        a, b = _P[pa], _P[pb]
        if counts[a, b] >= min_edges:
            raw[name] = (_push(centres[a, b], radius * scale), min(1.0, counts[a, b] / 4.0))
    out = dict(raw)
    for side, other in (("right", "left"), ("left", "right")):
        knee, hip = raw.get(f"{side}_knee"), raw.get(f"{side}_hip")
        if knee is not None and hip is not None:
            up = _unit(hip[0] - knee[0])
            out[f"{side}_knee"] = (knee[0] + 0.035 * scale * up, knee[1])
            lateral = np.zeros(3)
            if f"{other}_hip" in raw:
                lat = hip[0] - raw[f"{other}_hip"][0]
                lat = lat - (lat @ up) * up
                lateral = 0.025 * scale * _unit(lat)
            if np.isfinite(lateral).all():
                out[f"{side}_hip"] = (hip[0] + 0.035 * scale * up + lateral, hip[1])
        elif hip is not None:
            del out[f"{side}_hip"]
    trunk_up = None
    if "neck" in raw and "right_hip" in out and "left_hip" in out:
        trunk_up = _unit(raw["neck"][0] - 0.5 * (out["right_hip"][0] + out["left_hip"][0]))
    for side in ("right", "left"):
        name = f"{side}_shoulder"
        if name in out:
            if trunk_up is not None and np.isfinite(trunk_up).all():
                out[name] = (raw[name][0] + 0.045 * scale * trunk_up, raw[name][1])
            else:
                del out[name]
    return out


def fit_skeleton(
    points: np.ndarray,
    labels: np.ndarray,
    *,
    bone_lengths: np.ndarray,
    edges: tuple[np.ndarray, np.ndarray],
    modes: np.ndarray | None = None,
    prediction: np.ndarray | None = None,
    height: float | None = None,
    min_edges: int = 2,
    min_part_points: int = 4,
    min_elongation: float = 3.0,
    smoothing: float = 0.0,
) -> SkeletonFit:
    """Fit the 15-joint skeleton to labelled points with calibrated bone lengths.

    Ring joints (neck, elbows, knees, and where seen wrists, ankles, shoulders and
    hips) come from part boundaries (:func:`ring_joints`). Each limb bone starts at
    its elbow or knee and follows a direction that mixes the part's principal axis
    (oriented towards its mode) and the direction to the ring joint at its other
    end (:data:`LIMB_DIRECTION_WEIGHTS`), for exactly its calibrated length.

    Parameters
    ----------
    points : (N, 3) float
        Camera-frame points in metres.
    labels : (N,) int
        Part of each point (``PART_NAMES``).
    bone_lengths : (15,) float
        ``|joint_i - joint_parent(i)|`` in metres (``JOINT_PARENTS``), from calibration.
    edges : (rows (E,), cols (E,))
        Neighbour pairs (e.g. :class:`posedrift.labelling.GeodesicGraph` edges).
    modes : (15, 3) float, optional
        Mean-shift mode of each part (computed from the points where not given).
    prediction : (15, 3) float, optional
        Predicted joints (previous skeleton moved by the registration), used where
        the labels do not support a joint, and blended in by ``smoothing``.
    height : float, optional
        Stature in metres (scales the boundary corrections); from the bone lengths
        where not given.
    min_edges : int
        Fewest boundary edges for a ring joint to count as measured.
    min_part_points : int
        Fewest points for a part's axis.
    min_elongation : float
        Smallest ``lambda1 / lambda2`` for a part's principal axis to be trusted.
    smoothing : float
        Weight of the prediction in each measured joint, in [0, 1).

    Returns
    -------
    SkeletonFit
    """
    from posedrift.skeleton._meanshift import part_modes

    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels).astype(np.int64)
    bone_lengths = np.asarray(bone_lengths, dtype=float)
    if height is None:
        height = float(bone_lengths[_J["right_foot"]] / SEGMENT_RATIOS["shank"])
    rows, cols = edges
    if modes is None:
        modes = part_modes(points, labels, bandwidth=0.06)
    counts = np.bincount(labels[(labels >= 0) & (labels < N_PARTS)], minlength=N_PARTS)
    pred = None if prediction is None else np.asarray(prediction, dtype=float)
    centres, ecounts = part_boundaries(points, labels, rows, cols)
    axes, elong = part_axes(points, labels, min_points=min_part_points)
    ring = ring_joints(centres, ecounts, height=height, min_edges=min_edges)

    joints = np.full((15, 3), np.nan)
    conf = np.zeros(15)
    measured = np.zeros(15, dtype=bool)

    def blend(i: int, value: np.ndarray) -> np.ndarray:
        if smoothing > 0 and pred is not None and np.isfinite(pred[i]).all():
            return (1.0 - smoothing) * value + smoothing * pred[i]
        return value

    for name in ("neck", "right_elbow", "left_elbow", "right_knee", "left_knee"):
        i = _J[name]
        if name in ring:
            joints[i] = blend(i, ring[name][0])
            conf[i] = ring[name][1]
            measured[i] = True
        elif pred is not None and np.isfinite(pred[i]).all():
            joints[i] = pred[i]
            conf[i] = 0.3
        else:  # Between the modes of the two parts that meet there.
            pa, pb, _ = RING_JOINTS[name]
            between = 0.5 * (modes[_P[pa]] + modes[_P[pb]])
            if np.isfinite(between).all():
                joints[i] = _push(between, RING_JOINTS[name][2])
                conf[i] = 0.2

    modes_back = modes + PART_RADII[:, None] * (
        modes / np.maximum(np.linalg.norm(modes, axis=1, keepdims=True), 1e-9)
    )
    for anchor_name, part_name, joint_name in _LIMBS:
        ia, part, ij = _J[anchor_name], _P[part_name], _J[joint_name]
        length = bone_lengths[ij] if JOINT_PARENTS[ij] == ia else bone_lengths[ia]
        anchor = joints[ia]
        direction = np.full(3, np.nan)
        if np.isfinite(anchor).all() and counts[part] >= min_part_points:
            w_axis, w_ring = LIMB_DIRECTION_WEIGHTS[part_name.split("_", 1)[1]]
            to_mode = _unit(modes_back[part] - anchor)
            if elong[part] >= min_elongation and np.isfinite(to_mode).all():
                axis = axes[part]
                direction = axis if axis @ to_mode >= 0 else -axis
            else:
                direction = to_mode
            if joint_name in ring and w_ring > 0:
                to_ring = _unit(ring[joint_name][0] - anchor)
                if np.isfinite(to_ring).all():
                    direction = _unit(w_axis * direction + w_ring * to_ring)
        if np.isfinite(direction).all():
            joints[ij] = blend(ij, anchor + length * direction)
            conf[ij] = conf[ia] * min(1.0, counts[part] / 8.0)
            measured[ij] = measured[ia]
        elif pred is not None and np.isfinite(pred[ij]).all():
            if np.isfinite(anchor).all() and np.isfinite(pred[ia]).all():
                d = _unit(pred[ij] - pred[ia])
                joints[ij] = anchor + length * d if np.isfinite(d).all() else pred[ij]
            else:
                joints[ij] = pred[ij]
            conf[ij] = 0.3 * max(conf[ia], 0.5)

    # Head: from the neck towards the head's mode.
    ih, ineck = _J["head"], _J["neck"]
    if np.isfinite(joints[ineck]).all() and counts[_P["head"]] >= 1:
        d = _unit(modes_back[_P["head"]] - joints[ineck])
        if np.isfinite(d).all():
            joints[ih] = joints[ineck] + bone_lengths[ih] * d
            conf[ih] = min(1.0, counts[_P["head"]] / 8.0) * max(conf[ineck], 0.5)
            measured[ih] = True
    if not np.isfinite(joints[ih]).all() and pred is not None:
        joints[ih] = pred[ih]
        conf[ih] = 0.3
    # Torso: midpoint of neck and pelvis centre.
    it = _J["torso"]
    pelvis = 0.5 * (joints[_J["right_hip"]] + joints[_J["left_hip"]])
    joints[it] = 0.5 * (joints[ineck] + pelvis)
    if not np.isfinite(joints[it]).all() and pred is not None:
        joints[it] = pred[it]
    conf[it] = min(conf[ineck], conf[_J["right_hip"]], conf[_J["left_hip"]])
    measured[it] = measured[ineck] and measured[_J["right_hip"]] and measured[_J["left_hip"]]

    # Length agreement of measured ring-to-ring bones (health and confidence).
    ratio = np.full(15, np.nan)
    for child, parent in (
        ("right_hand", "right_elbow"),
        ("left_hand", "left_elbow"),
        ("right_foot", "right_knee"),
        ("left_foot", "left_knee"),
    ):
        if child in ring and parent in ring:
            dist = np.linalg.norm(ring[child][0] - ring[parent][0])
            ratio[_J[child]] = dist / max(bone_lengths[_J[child]], 1e-6)
            penalty = min(1.0, abs(ratio[_J[child]] - 1.0) / 0.5)
            conf[_J[child]] *= 1.0 - 0.5 * penalty
    conf = np.where(np.isfinite(joints).all(axis=1), np.clip(conf, 0.0, 1.0), 0.0)
    return SkeletonFit(joints=joints, confidence=conf, measured=measured, length_ratio=ratio)


def part_anchors(joints: np.ndarray, bone_lengths: np.ndarray) -> np.ndarray:
    """A point on each part's axis (its middle) from a skeleton: ``J_j`` for Algorithm 2.

    Hands and feet extend beyond the wrist and ankle along the forearm and shank.
    """
    j = np.asarray(joints, dtype=float)
    pelvis = 0.5 * (j[_J["right_hip"]] + j[_J["left_hip"]])
    out = np.full((N_PARTS, 3), np.nan)
    out[_P["head"]] = j[_J["head"]]
    out[_P["upper_torso"]] = 0.5 * (j[_J["neck"]] + j[_J["torso"]])
    out[_P["lower_torso"]] = 0.5 * (j[_J["torso"]] + pelvis)
    for side in ("right", "left"):
        sh, el, wr = j[_J[f"{side}_shoulder"]], j[_J[f"{side}_elbow"]], j[_J[f"{side}_hand"]]
        hip, kn, an = j[_J[f"{side}_hip"]], j[_J[f"{side}_knee"]], j[_J[f"{side}_foot"]]
        out[_P[f"{side}_upper_arm"]] = 0.5 * (sh + el)
        out[_P[f"{side}_forearm"]] = 0.5 * (el + wr)
        out[_P[f"{side}_thigh"]] = 0.5 * (hip + kn)
        out[_P[f"{side}_shank"]] = 0.5 * (kn + an)
        hand_dir = _unit(wr - el)
        out[_P[f"{side}_hand"]] = wr + 0.37 * bone_lengths[_J[f"{side}_hand"]] * hand_dir
        shank_dir = _unit(an - kn)
        out[_P[f"{side}_foot"]] = an + 0.03 * shank_dir
    return out


def bone_anchors(joints: np.ndarray, bone_lengths: np.ndarray, *, n: int = 3) -> np.ndarray:
    """``n`` points along each part's bone, ``(15, n, 3)``: multi-source ``J_j`` for Algorithm 2.

    The bones run between the part's two ends (``PART_JOINTS``; the pelvis is the
    mean of the hips, hands and feet extend beyond the wrist and ankle), sampled
    at ``(i + 0.5) / n`` of their length.
    """
    j = np.asarray(joints, dtype=float)
    pelvis = 0.5 * (j[_J["right_hip"]] + j[_J["left_hip"]])
    starts = np.full((N_PARTS, 3), np.nan)
    ends = np.full((N_PARTS, 3), np.nan)
    starts[_P["head"]], ends[_P["head"]] = j[_J["neck"]], j[_J["head"]]
    starts[_P["upper_torso"]], ends[_P["upper_torso"]] = j[_J["neck"]], j[_J["torso"]]
    starts[_P["lower_torso"]], ends[_P["lower_torso"]] = j[_J["torso"]], pelvis
    for side in ("right", "left"):
        sh, el, wr = j[_J[f"{side}_shoulder"]], j[_J[f"{side}_elbow"]], j[_J[f"{side}_hand"]]
        hip, kn, an = j[_J[f"{side}_hip"]], j[_J[f"{side}_knee"]], j[_J[f"{side}_foot"]]
        for part, a, b in (
            ("upper_arm", sh, el),
            ("forearm", el, wr),
            ("thigh", hip, kn),
            ("shank", kn, an),
        ):
            starts[_P[f"{side}_{part}"]], ends[_P[f"{side}_{part}"]] = a, b
        hand_len = 0.74 * bone_lengths[_J[f"{side}_hand"]]
        starts[_P[f"{side}_hand"]] = wr
        ends[_P[f"{side}_hand"]] = wr + hand_len * _unit(wr - el)
        starts[_P[f"{side}_foot"]] = an
        ends[_P[f"{side}_foot"]] = an + 0.1 * bone_lengths[_J[f"{side}_foot"]] * _unit(an - kn)
    t = (np.arange(n) + 0.5) / n
    return starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]
