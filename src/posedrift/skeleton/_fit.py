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

import math
from dataclasses import dataclass

import numpy as np

from posedrift.camera import Intrinsics
from posedrift.skeleton._definitions import (
    JOINT_INDEX,
    JOINT_PARENTS,
    PART_INDEX,
    PART_JOINTS,
    SEGMENT_RATIOS,
)

_J = JOINT_INDEX
_P = PART_INDEX
N_PARTS = 15

# Ring joints: joint -> (part a, part b, push-back radius in metres at a 1.75 m stature).
# The radii here and in PART_RADII were set with the skeleton stage fed true labels
# (benchmarks/label_oracle.py): 1.3 times the first, anatomical guesses, which left the
# joints in front of the bones (five clips: 5.25 -> 4.70 degrees with true labels).
RING_JOINTS: dict[str, tuple[str, str, float]] = {
    "neck": ("head", "upper_torso", 0.065),
    "right_elbow": ("right_upper_arm", "right_forearm", 0.0455),
    "left_elbow": ("left_upper_arm", "left_forearm", 0.0455),
    "right_hand": ("right_forearm", "right_hand", 0.0325),
    "left_hand": ("left_forearm", "left_hand", 0.0325),
    "right_knee": ("right_thigh", "right_shank", 0.026),
    "left_knee": ("left_thigh", "left_shank", 0.026),
    "right_foot": ("right_shank", "right_foot", 0.039),
    "left_foot": ("left_shank", "left_foot", 0.039),
    "right_shoulder": ("upper_torso", "right_upper_arm", 0.065),
    "left_shoulder": ("upper_torso", "left_upper_arm", 0.065),
    "right_hip": ("lower_torso", "right_thigh", 0.1235),
    "left_hip": ("lower_torso", "left_thigh", 0.1235),
}

# How far up the upper arm the upper-arm/forearm boundary lies from the elbow, at a 1.75 m
# stature. On the body model with true labels the boundary's centre lies 27 mm up the arm
# on the forest's training clips (scripts/measure_ring_offsets.py, "down the limb"), and
# the pushed-back boundary joint 33 mm on the held-out walks, 40 on the development clips:
# about 29 with the arm straight, 41-52 bent. The skeleton's fit moves its elbows that far
# down the arm; the limb lengths are measured between the boundaries as they lie
# (tracking's calibration), which gave the tracker's upper arm 259-260 mm against a true
# 252 where the moved elbows gave it 291-295.
ELBOW_BOUNDARY_SHIFT = 0.035
# With the arm straight in a T-pose the boundary lies 5-10 mm from the elbow (the elbows of
# the calibration frame 10 mm from the truth unmoved, 31-34 moved the full shift): the shift
# grows with the bend measured between the boundaries, in full from this many degrees.
ELBOW_FULL_SHIFT_BEND = 30.0
# How far up the thigh each knee is moved from the thigh/shank boundary, at a 1.75 m
# stature. With true labels the boundary lies 15 mm below the knee (the script above),
# but on the tracker's own labels 25-35 mm gave the lowest knee errors (15 and 45 mm
# worse on the development and held-out clips, one sample each): its labels put the
# boundary lower than the truth does.
KNEE_BOUNDARY_SHIFT = 0.035
# Where a limb's far ring joint is unseen, the predicted far joint (the last skeleton,
# carried by the registration) joins the evidence that turns the limb's axis, at this
# weight: a forearm pointed at the camera has its mode a few centimetres from the
# elbow, behind it once both are pushed back, and its wrist hidden by the hand.
PREDICTED_SIGN_WEIGHT = 0.5

# Push-back radii for a person seen from behind, at a 1.75 m stature. From behind, the
# boundaries lie elsewhere on the body: on the body model with true labels, the hip's
# boundary (the fold of the buttocks) is 33 mm in front of the joint against 95 mm from
# the front, the knee's (its hollow) 52 against 18 mm, the elbow's 17 against 34 mm.
# Each radius above is shifted by that difference, measured on the forest's training
# clips (scripts/measure_ring_offsets.py); a person turned beyond side-on gets a blend
# (ring_joints' ``facing``).
RING_BACK_RADII: dict[str, float] = {
    "neck": 0.058,
    "right_elbow": 0.029,
    "left_elbow": 0.029,
    "right_hand": 0.028,
    "left_hand": 0.028,
    "right_knee": 0.059,
    "left_knee": 0.059,
    "right_foot": 0.033,
    "left_foot": 0.033,
    "right_shoulder": 0.052,
    "left_shoulder": 0.052,
    "right_hip": 0.062,
    "left_hip": 0.062,
}

# Radius (metres) by which a part's visible surface lies in front of its axis.
PART_RADII = np.array(
    [0.091, 0.117, 0.117, 0.0455, 0.0455, 0.039, 0.039, 0.026, 0.026, 0.078, 0.078]
    + [0.0585, 0.0585, 0.039, 0.039]
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

# How far the hips' line may tilt from square to the trunk (neck to pelvis centre), degrees,
# when the pelvis is braced. In the development and held-out clips' ground truth the tilt
# has a median of 1.7-4.1 degrees and a 90th percentile of 5-10 (the built-in motion's
# pelvis is square); a hip the thighs place 5-6 cm low behind a crossing leg reads 12.
PELVIS_TILT_LIMIT = 6.0

_XYZ = np.arange(3)
_UPPER = np.triu_indices(N_PARTS, 1)
# Upper triangle of a 3 x 3 covariance (i <= j) and where each of its 9 entries comes from.
_COV_I = np.array([0, 0, 0, 1, 1, 2])
_COV_J = np.array([0, 1, 2, 1, 2, 2])
_COV_FULL = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])


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
    neck_y = (r["shoulder_height"] + r["neck_above_shoulders"]) * h
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
    pelvis_width : float
        Metres between the hips as the thighs placed them, before any bracing
        (``fit_skeleton``'s ``pelvis_width``); NaN where a hip is unknown.
    """

    joints: np.ndarray
    confidence: np.ndarray
    measured: np.ndarray
    length_ratio: np.ndarray
    pelvis_width: float = math.nan


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
    ok = la != lb
    if len(labels) and (labels.min() < 0 or labels.max() >= N_PARTS):  # unknown labels
        ok &= (la >= 0) & (lb >= 0) & (la < N_PARTS) & (lb < N_PARTS)
    la, lb = la[ok], lb[ok]
    a, b = np.minimum(la, lb), np.maximum(la, lb)
    code = a * N_PARTS + b
    mid = 0.5 * (points[rows[ok]] + points[cols[ok]])
    counts = np.bincount(code, minlength=N_PARTS * N_PARTS)
    # One bincount for the three coordinates (bin 3 * code + d): each bin still adds its
    # edges in edge order, so the sums are those of one bincount per coordinate.
    sums = np.bincount(
        (3 * code[:, None] + _XYZ).ravel(), weights=mid.ravel(), minlength=3 * N_PARTS * N_PARTS
    ).reshape(N_PARTS * N_PARTS, 3)
    centres = np.full((N_PARTS * N_PARTS, 3), np.nan)
    have = counts > 0
    centres[have] = sums[have] / counts[have, None]
    centres = centres.reshape(N_PARTS, N_PARTS, 3)
    counts = counts.reshape(N_PARTS, N_PARTS)
    centres[_UPPER[1], _UPPER[0]] = centres[_UPPER]
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
    if ok.all():  # the usual case: no copies
        lab, p = labels, points
    else:
        lab, p = labels[ok], points[ok]
    counts = np.bincount(lab, minlength=N_PARTS)
    # Per-part sums by one bincount over (part, component) bins; each bin adds its points
    # in point order, as one bincount per component would.
    means = _part_sums(lab, p) / np.maximum(counts, 1)[:, None]
    c = p - means[lab]
    cov = _part_sums(lab, c[:, _COV_I] * c[:, _COV_J])[:, _COV_FULL].reshape(N_PARTS, 3, 3)
    good = counts >= min_points
    if good.any():
        w, v = np.linalg.eigh(cov[good])
        axes[good] = v[:, :, 2]
        elong[good] = w[:, 2] / np.maximum(w[:, 1], 1e-12)
    return axes, elong


def _part_sums(lab: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Sum ``(15, K)`` of the rows of ``values (N, K)`` by part ``lab (N,)``."""
    k = values.shape[1]
    bins = (k * lab[:, None] + np.arange(k)).ravel()
    return np.bincount(bins, weights=values.ravel(), minlength=k * N_PARTS).reshape(N_PARTS, k)


def image_exits(
    points: np.ndarray,
    labels: np.ndarray,
    intrinsics: Intrinsics,
    *,
    margin: float = 1.0,
    voxel_size: float = 0.0,
) -> np.ndarray:
    """Where each part leaves the image: ``(15, 3)``, NaN for parts inside it.

    The centroid of each part's points at the image's edge: a part with such
    points is cut off by the edge (its mode lies on the stub in view).

    Parameters
    ----------
    points : (N, 3) float
        Camera-frame points in metres.
    labels : (N,) int
        Part of each point; labels outside 0-14 are ignored.
    intrinsics : Intrinsics
        The camera whose image the points come from.
    margin : float
        A point within this many pixels of the border is at the edge (1: a point
        back-projected from a border pixel).
    voxel_size : float
        Where the points are centroids of downsampling voxels of this size (metres),
        the margin grows by a voxel's size in pixels at each point's depth: a
        centroid lies inside the pixels it stands for.
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels)
    k = intrinsics
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):  # project()'s arithmetic, inline
        u = k.fx * x / z + k.cx
        v = k.fy * y / z + k.cy
        margin = margin + voxel_size * k.fx / z
    at = (u < margin) | (u > k.width - 1 - margin) | (v < margin) | (v > k.height - 1 - margin)
    out = np.full((N_PARTS, 3), np.nan)
    if not at.any():
        return out
    at &= (labels >= 0) & (labels < N_PARTS)
    if at.any():
        counts = np.bincount(labels[at], minlength=N_PARTS)
        seen = counts > 0
        out[seen] = (_part_sums(labels[at], points[at]) / np.maximum(counts, 1)[:, None])[seen]
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    # np.linalg.norm of a 1-D float vector is sqrt(v.dot(v)); this skips its overhead.
    n = math.sqrt(v.dot(v))
    return v / n if n > 1e-12 else np.full(3, np.nan)


def _clamp(x: float) -> float:
    """``np.clip(x, -1, 1)`` of a scalar (NaN stays NaN), without the ufunc's overhead."""
    return x if math.isnan(x) else min(1.0, max(-1.0, x))


def _finite(v: np.ndarray) -> bool:
    """``np.isfinite(v).all()`` for a 3-vector, without the ufunc overhead."""
    return math.isfinite(v[0]) and math.isfinite(v[1]) and math.isfinite(v[2])


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

# _LIMBS as index arrays (for placing the eight limb joints at once), with their direction
# weights: the tables above are read once, at import.
_LIMB_ANCHOR = np.array([_J[a] for a, _, _ in _LIMBS])
_LIMB_PART = np.array([_P[p] for _, p, _ in _LIMBS])
_LIMB_JOINT = np.array([_J[j] for _, _, j in _LIMBS])
_LIMB_NAMES = tuple(j for _, _, j in _LIMBS)
# The bone of each limb joint: its own where its parent is the anchor, else the anchor's.
_LIMB_LENGTH = np.array(
    [j if JOINT_PARENTS[j] == a else a for a, j in zip(_LIMB_ANCHOR, _LIMB_JOINT, strict=True)]
)
_LIMB_W_AXIS, _LIMB_W_RING = (
    np.array([LIMB_DIRECTION_WEIGHTS[p.split("_", 1)[1]][k] for _, p, _ in _LIMBS])[:, None]
    for k in (0, 1)
)
# The two parts meeting at each limb's anchor (its ring joint).
_LIMB_ANCHOR_PARTS = tuple(np.array([_P[RING_JOINTS[a][k]] for a, _, _ in _LIMBS]) for k in (0, 1))
_NAN3 = np.full(3, np.nan)
# RING_JOINTS as arrays: the two parts meeting at each ring joint and its radius.
_RING_NAMES = tuple(RING_JOINTS)
_RING_A = np.array([_P[a] for a, _, _ in RING_JOINTS.values()])
_RING_B = np.array([_P[b] for _, b, _ in RING_JOINTS.values()])
_RING_RADII = np.array([r for _, _, r in RING_JOINTS.values()])
_RING_BACK_RADII = np.array([RING_BACK_RADII[name] for name in RING_JOINTS])


def ring_joints(
    centres: np.ndarray,
    counts: np.ndarray,
    *,
    height: float,
    min_edges: int = 2,
    facing: float | None = None,
    elbow_shift: float = 0.0,
) -> dict[str, tuple[np.ndarray, float]]:
    """Joint estimates from part boundaries, corrected for where the boundaries lie.

    Boundaries lie on the visible surface: each is pushed back along its camera ray
    by the limb's radius (:data:`RING_JOINTS`; seen from behind, where the boundaries
    lie elsewhere on the body, :data:`RING_BACK_RADII`: a person turned ``facing``
    degrees away, beyond 90, gets ``w = -cos(facing)`` of the second). The thigh/shank
    boundary sits below the knee, the torso/thigh boundary below and inside the hip,
    the torso/upper-arm boundary below the shoulder: fixed offsets (scaled by
    stature) move them onto the joints. ``facing`` None or NaN: seen from the front.
    ``elbow_shift`` (metres at a 1.75 m stature) moves each elbow that far down its
    arm, away from the shoulder's boundary: the skeleton's fit uses
    :data:`ELBOW_BOUNDARY_SHIFT`, the limbs' measurement none.

    Returns
    -------
    dict
        ``joint name -> (position (3,), support in [0, 1])`` for the boundaries seen.
    """
    scale = height / 1.75
    # All thirteen boundaries pushed back at once (unseen ones are NaN and dropped).
    edges = counts[_RING_A, _RING_B]
    seen = centres[_RING_A, _RING_B]
    radii = _RING_RADII
    if facing is not None and math.isfinite(facing):
        # From facing the camera to side-on the front radii; beyond, a blend to the back.
        behind = max(0.0, -math.cos(math.radians(facing)))
        radii = (1.0 - behind) * _RING_RADII + behind * _RING_BACK_RADII
    pushed = seen + (radii * scale)[:, None] * _units(seen)
    support = np.minimum(1.0, edges / 4.0)
    raw = {_RING_NAMES[k]: (pushed[k], support[k]) for k in np.flatnonzero(edges >= min_edges)}
    out = dict(raw)
    for side in ("right", "left") if elbow_shift else ():
        elbow, shoulder = raw.get(f"{side}_elbow"), raw.get(f"{side}_shoulder")
        if elbow is not None and shoulder is not None:
            down = _unit(elbow[0] - shoulder[0])
            wrist = raw.get(f"{side}_hand")
            share = 1.0  # of the shift, by how far the arm is bent (none straight)
            if wrist is not None:
                bend = math.degrees(math.acos(_clamp(down @ _unit(wrist[0] - elbow[0]))))
                share = min(1.0, bend / ELBOW_FULL_SHIFT_BEND) if math.isfinite(bend) else 1.0
            down = share * elbow_shift * scale * down
            if _finite(down):
                out[f"{side}_elbow"] = (elbow[0] + down, elbow[1])
    for side, other in (("right", "left"), ("left", "right")):
        knee, hip = raw.get(f"{side}_knee"), raw.get(f"{side}_hip")
        if knee is not None and hip is not None:
            up = _unit(hip[0] - knee[0])
            out[f"{side}_knee"] = (knee[0] + KNEE_BOUNDARY_SHIFT * scale * up, knee[1])
            lateral = np.zeros(3)
            if f"{other}_hip" in raw:
                lat = hip[0] - raw[f"{other}_hip"][0]
                lat = lat - (lat @ up) * up
                lateral = 0.025 * scale * _unit(lat)
            if _finite(lateral):
                out[f"{side}_hip"] = (hip[0] + 0.035 * scale * up + lateral, hip[1])
        elif hip is not None:
            del out[f"{side}_hip"]
    trunk_up = None
    if "neck" in raw and "right_hip" in out and "left_hip" in out:
        trunk_up = _unit(raw["neck"][0] - 0.5 * (out["right_hip"][0] + out["left_hip"][0]))
    for side in ("right", "left"):
        name = f"{side}_shoulder"
        if name in out:
            if trunk_up is not None and _finite(trunk_up):
                out[name] = (raw[name][0] + 0.045 * scale * trunk_up, raw[name][1])
            else:
                del out[name]
    return out


def _units(v: np.ndarray) -> np.ndarray:
    """:func:`_unit` of each row of ``v (K, 3)`` (the same norms).

    A stack of (1 x 3) @ (3 x 1) products: matmul takes each by the BLAS dot that
    ``row.dot(row)`` calls (the same sums), without a Python loop over the rows.
    """
    norms = np.sqrt(np.matmul(v[:, None, :], v[:, :, None])[:, 0, 0])
    big = norms > 1e-12  # False for NaN
    out = v / np.where(big, norms, 1.0)[:, None]
    out[~big] = np.nan
    return out


def _finite_or_zero(v: np.ndarray) -> np.ndarray:
    """``v (K, 3)`` with its rows that are not finite set to zero."""
    return np.where(_rows_finite(v)[:, None], v, 0.0)


def _rows_finite(v: np.ndarray) -> np.ndarray:
    """Whether each row of ``v (K, 3)`` is finite."""
    return np.isfinite(v).all(axis=1)


def _place_limbs(
    joints: np.ndarray,
    conf: np.ndarray,
    measured: np.ndarray,
    *,
    bone_lengths: np.ndarray,
    counts: np.ndarray,
    modes: np.ndarray,
    modes_back: np.ndarray,
    boundaries: np.ndarray,
    exits: np.ndarray,
    axes: np.ndarray,
    elong: np.ndarray,
    ring: dict[str, tuple[np.ndarray, float]],
    pred: np.ndarray | None,
    smoothing: float,
    min_part_points: int,
    min_elongation: float,
) -> None:
    """Place the eight limb joints of :data:`_LIMBS` from their anchors, in place.

    All eight at once (they depend only on their anchors, placed before): each
    follows a mix of its part's oriented principal axis (or the direction to the
    part's mode) and the direction to its own ring joint, for its bone length.
    Joints without a direction fall back on the prediction.

    A part cut off by the image's edge (``exits``: where each part leaves the
    image, :func:`image_exits`) shows a stub whose mode lies close to the anchor;
    from the pushed-back anchor to the pushed-back mode (``modes_back``) the two
    push-back radii (ring joint and part) differ, and over so short a distance that
    difference bends the limb (a shank cut below the knee by the lower edge read
    18-20 degrees bent). Such a limb takes its direction on the visible surface
    instead, from the centre of its anchor's boundary (``boundaries``:
    :func:`part_boundaries`' centres), which lies about as far in front of the bone,
    towards where the part leaves the image where that lies beyond the mode (the
    longer baseline: the limb runs on out of the image), else towards the mode.
    Whole parts keep the pushed-back direction: between arms that hide each other a
    boundary's centre mixes near and far surfaces.
    """
    ia, part, ij = _LIMB_ANCHOR, _LIMB_PART, _LIMB_JOINT
    lengths = bone_lengths[_LIMB_LENGTH]
    anchor = joints[ia]
    live = _rows_finite(anchor) & (counts[part] >= min_part_points)
    to_mode = _units(modes_back[part] - anchor)
    cut = np.isfinite(exits[part, 0])
    if cut.any():
        base = boundaries[_LIMB_ANCHOR_PARTS]
        along, out = modes[part] - base, exits[part] - base
        beyond = (out * along).sum(axis=1) >= (along * along).sum(axis=1)  # False for NaN
        on_surface = _units(np.where(beyond[:, None], out, along))
        surface = cut & _rows_finite(on_surface)
        to_mode[surface] = on_surface[surface]
    # The part's axis, where the part is elongated enough, turned towards the far end
    # it sees: the offsets to its mode and to the ring joint at its far end, summed
    # unnormalised so that the longer baseline decides. A mode a few centimetres from
    # the anchor, on the wrong side of it after a poor labelling, would otherwise turn
    # a forearm whose wrist is seen end for end. Where the far end is unseen, the
    # predicted far joint joins them (PREDICTED_SIGN_WEIGHT).
    axis = axes[part]
    use_axis = live & (elong[part] >= min_elongation) & _rows_finite(to_mode)
    far = np.array([ring[name][0] if name in ring else _NAN3 for name in _LIMB_NAMES])
    reach = np.linalg.norm(modes_back[part] - anchor, axis=1)
    towards = _finite_or_zero(to_mode * reach[:, None]) + _finite_or_zero(far - anchor)
    if pred is not None:
        unseen = ~_rows_finite(far)
        towards[unseen] += PREDICTED_SIGN_WEIGHT * _finite_or_zero(pred[ij] - anchor)[unseen]
    facing = (axis * towards).sum(axis=1) >= 0  # the sign of axis @ towards
    direction = np.where(use_axis[:, None], np.where(facing[:, None], axis, -axis), to_mode)
    direction[~live] = np.nan
    # Mixed with the direction to the ring joint at the limb's far end, where seen.
    to_ring = _units(far - anchor)
    mix = live & (_LIMB_W_RING[:, 0] > 0) & _rows_finite(to_ring)
    if mix.any():
        mixed = _units(_LIMB_W_AXIS[mix] * direction[mix] + _LIMB_W_RING[mix] * to_ring[mix])
        direction[mix] = mixed
    placed = _rows_finite(direction)
    value = anchor + lengths[:, None] * direction
    if smoothing > 0 and pred is not None:
        smooth = placed & _rows_finite(pred[ij])
        value[smooth] = (1.0 - smoothing) * value[smooth] + smoothing * pred[ij][smooth]
        # Smoothing turns the bone, never stretches it: back to its length.
        value[smooth] = anchor[smooth] + lengths[smooth, None] * _units(
            value[smooth] - anchor[smooth]
        )
    joints[ij[placed]] = value[placed]
    conf[ij[placed]] = (conf[ia] * np.minimum(1.0, counts[part] / 8.0))[placed]
    measured[ij[placed]] = measured[ia[placed]]
    if pred is None:
        return
    for k in np.flatnonzero(~placed):  # Rare: follow the predicted bone's direction.
        a, j = ia[k], ij[k]
        if not _finite(pred[j]):
            continue
        if _finite(anchor[k]):
            d = _unit(pred[j] - (pred[a] if _finite(pred[a]) else anchor[k]))
            joints[j] = anchor[k] + lengths[k] * d if _finite(d) else pred[j]
        else:
            joints[j] = pred[j]
        conf[j] = 0.3 * max(conf[a], 0.5)


def _trunk_axes(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The trunk's ``up`` (pelvis centre to neck) and ``rightwards`` (across the hips) units."""
    right_hip, left_hip = joints[_J["right_hip"]], joints[_J["left_hip"]]
    up = _unit(joints[_J["neck"]] - 0.5 * (right_hip + left_hip))
    across = right_hip - left_hip
    return up, _unit(across - (across @ up) * up)


def shoulder_offset_of(joints: np.ndarray) -> np.ndarray:
    """Where a skeleton's shoulders sit from its neck: ``(across, below)`` in metres.

    ``across`` along the hips' line and ``below`` down the trunk's axis, the two
    sides averaged; NaN where the trunk or a shoulder is unknown. The offset
    :func:`fit_skeleton` anchors the shoulders to (``shoulder_offset=``).
    """
    joints = np.asarray(joints, dtype=float)
    up, rightwards = _trunk_axes(joints)
    out = np.zeros(2)
    for side, sign in (("right", 1.0), ("left", -1.0)):
        d = joints[_J[f"{side}_shoulder"]] - joints[_J["neck"]]
        out += 0.5 * np.array([sign * (d @ rightwards), -(d @ up)])
    return out


def _anchor_shoulders(
    joints: np.ndarray,
    *,
    bone_lengths: np.ndarray,
    height: float,
    weight: float,
    offset: np.ndarray | None = None,
) -> None:
    """Pull each shoulder towards where the trunk puts it, carrying its arm along; in place.

    The shoulder a limb chain places (elbow minus the upper arm's measured direction)
    follows every mislabelled point of an arm that is often half hidden; the trunk
    fixes it better: beside the neck across the hips' line, ``offset`` (``(across,
    below)`` metres, as :func:`shoulder_offset_of` measures it) from the neck, by
    default the T-pose's geometry (the calibrated bone length,
    ``neck_above_shoulders`` of stature below the neck). Each shoulder moves
    ``weight`` of the way there; its elbow then keeps its direction from the new
    shoulder at the upper arm's length, and the hand moves with the elbow (the
    forearm keeps its direction and length).
    """
    up, rightwards = _trunk_axes(joints)
    if not (_finite(up) and _finite(rightwards)):
        return
    neck = joints[_J["neck"]]
    for side, sign in (("right", 1.0), ("left", -1.0)):
        shoulder, elbow, hand = (_J[f"{side}_{j}"] for j in ("shoulder", "elbow", "hand"))
        if not (_finite(joints[shoulder]) and _finite(joints[elbow])):
            continue
        if offset is None:
            length = bone_lengths[shoulder]
            below = min(SEGMENT_RATIOS["neck_above_shoulders"] * height, 0.9 * length)
            across = math.sqrt(length**2 - below**2)
        else:
            across, below = offset
        on_trunk = neck + sign * across * rightwards - below * up
        moved = (1.0 - weight) * joints[shoulder] + weight * on_trunk
        new_elbow = moved + bone_lengths[elbow] * _unit(joints[elbow] - moved)
        if not _finite(new_elbow):
            continue
        joints[hand] += new_elbow - joints[elbow]
        joints[shoulder], joints[elbow] = moved, new_elbow


def _pelvis_width(joints: np.ndarray) -> float:
    """Metres between the two hips; NaN where either is unknown."""
    gap = joints[_J["right_hip"]] - joints[_J["left_hip"]]
    return math.sqrt(gap.dot(gap)) if _finite(gap) else math.nan


def _brace_pelvis(
    joints: np.ndarray, *, bone_lengths: np.ndarray, width: float, max_tilt: float
) -> None:
    """Set the hips ``width`` apart about their midpoint, tilted at most ``max_tilt``; in place.

    The pelvis is rigid, but each hip is placed from its own knee up its thigh: a hip
    hidden behind the other leg, or a thigh read from a few points, moves it alone.
    The width is the person's (the tracker's running median); the tilt is measured
    against the square to the trunk's axis (neck to pelvis centre), and a line tilted
    further is turned back to the limit in the plane of the trunk's axis. The knees
    and feet stay where they were measured: each hip is then set on its thigh, at the
    thigh's length from the knee towards where the brace puts it.
    """
    right, left = _J["right_hip"], _J["left_hip"]
    centre = 0.5 * (joints[right] + joints[left])
    up = _unit(joints[_J["neck"]] - centre)
    across = joints[right] - joints[left]
    if not (_finite(up) and _finite(across) and math.isfinite(width)):
        return
    rise = float(across @ up)
    square = _unit(across - rise * up)
    if not _finite(square):  # the hips' line along the trunk: no sideways to keep
        return
    limit = math.radians(max_tilt)
    tilt = min(math.atan2(abs(rise), math.sqrt(max(across @ across - rise * rise, 0.0))), limit)
    direction = math.cos(tilt) * square + math.copysign(math.sin(tilt), rise) * up
    for side, sign in (("right", 0.5), ("left", -0.5)):
        hip, knee = _J[f"{side}_hip"], _J[f"{side}_knee"]
        braced = centre + sign * width * direction
        # The knee is measured, the hip inferred: the thigh turns to the braced hip and
        # keeps its length (a few millimetres off the width, for centimetres moved).
        thigh = _unit(braced - joints[knee])
        joints[hip] = joints[knee] + bone_lengths[knee] * thigh if _finite(thigh) else braced


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
    shoulder_anchor: float = 0.3,
    shoulder_offset: np.ndarray | None = None,
    exits: np.ndarray | None = None,
    facing: float | None = None,
    elbow_shift: float = ELBOW_BOUNDARY_SHIFT,
    pelvis_width: float | None = None,
) -> SkeletonFit:
    """Fit the 15-joint skeleton to labelled points with calibrated bone lengths.

    Ring joints (neck, elbows, knees, and where seen wrists, ankles, shoulders and
    hips) come from part boundaries (:func:`ring_joints`). Each limb bone starts at
    its elbow or knee and follows a direction that mixes the part's principal axis
    (oriented towards its mode and its far ring joint) and the direction to that
    ring joint (:data:`LIMB_DIRECTION_WEIGHTS`), for exactly its calibrated length. The
    shoulders are then pulled towards where the trunk puts them (``shoulder_anchor``).

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
    shoulder_anchor : float
        How far each shoulder is pulled, in [0, 1], from where its arm puts it
        towards where the trunk puts it (the arm follows; :func:`_anchor_shoulders`).
    shoulder_offset : (2,) float, optional
        Where the trunk puts the shoulders: ``(across, below)`` the neck in metres
        (:func:`shoulder_offset_of` a calibration skeleton); the T-pose's geometry
        where not given.
    exits : (15, 3) float, optional
        Where each part leaves the image (:func:`image_exits`; NaN for parts inside
        it): a limb whose part is cut off by the image's edge takes its direction on
        the visible surface (see ``_place_limbs``). None: no part is cut.
    facing : float, optional
        How far the person is turned from the camera, degrees
        (:func:`posedrift.skeleton.facing_yaw` of the prediction, say): sets the
        ring joints' push-back radii (:func:`ring_joints`). None: seen from the front.
    elbow_shift : float
        How far the elbows are moved down the arm from their boundary, metres at a
        1.75 m stature (:data:`ELBOW_BOUNDARY_SHIFT`; 0 to measure the limbs between
        the boundaries as they lie, as the tracker's calibration does).
    pelvis_width : float, optional
        Brace the pelvis (beyond the paper): the hips, which the thighs place, are
        set this many metres apart about their midpoint, their line tilted at most
        :data:`PELVIS_TILT_LIMIT` degrees from square to the trunk, each at its
        thigh's length from its knee (see :func:`_brace_pelvis`). The tracker
        passes the median of the widths it measured (``SkeletonFit.pelvis_width``).
        None leaves the hips as placed.

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
    ring = ring_joints(
        centres,
        ecounts,
        height=height,
        min_edges=min_edges,
        facing=facing,
        elbow_shift=elbow_shift,
    )

    joints = np.full((15, 3), np.nan)
    conf = np.zeros(15)
    measured = np.zeros(15, dtype=bool)

    def blend(i: int, value: np.ndarray) -> np.ndarray:
        if smoothing > 0 and pred is not None and _finite(pred[i]):
            return (1.0 - smoothing) * value + smoothing * pred[i]
        return value

    for name in ("neck", "right_elbow", "left_elbow", "right_knee", "left_knee"):
        i = _J[name]
        if name in ring:
            joints[i] = blend(i, ring[name][0])
            conf[i] = ring[name][1]
            measured[i] = True
        elif pred is not None and _finite(pred[i]):
            joints[i] = pred[i]
            conf[i] = 0.3
        else:  # Between the modes of the two parts that meet there.
            pa, pb, _ = RING_JOINTS[name]
            between = 0.5 * (modes[_P[pa]] + modes[_P[pb]])
            if _finite(between):
                joints[i] = _push(between, RING_JOINTS[name][2])
                conf[i] = 0.2

    modes_back = modes + PART_RADII[:, None] * (
        modes / np.maximum(np.linalg.norm(modes, axis=1, keepdims=True), 1e-9)
    )
    _place_limbs(
        joints,
        conf,
        measured,
        bone_lengths=bone_lengths,
        counts=counts,
        modes=modes,
        modes_back=modes_back,
        boundaries=centres,
        exits=np.full((N_PARTS, 3), np.nan) if exits is None else np.asarray(exits, dtype=float),
        axes=axes,
        elong=elong,
        ring=ring,
        pred=pred,
        smoothing=smoothing,
        min_part_points=min_part_points,
        min_elongation=min_elongation,
    )
    if shoulder_anchor > 0:
        _anchor_shoulders(
            joints,
            bone_lengths=bone_lengths,
            height=height,
            weight=shoulder_anchor,
            offset=shoulder_offset,
        )

    placed_width = _pelvis_width(joints)
    if pelvis_width is not None:
        _brace_pelvis(
            joints, bone_lengths=bone_lengths, width=pelvis_width, max_tilt=PELVIS_TILT_LIMIT
        )

    # Head: from the neck towards the head's mode.
    ih, ineck = _J["head"], _J["neck"]
    if _finite(joints[ineck]) and counts[_P["head"]] >= 1:
        d = _unit(modes_back[_P["head"]] - joints[ineck])
        if _finite(d):
            joints[ih] = joints[ineck] + bone_lengths[ih] * d
            conf[ih] = min(1.0, counts[_P["head"]] / 8.0) * max(conf[ineck], 0.5)
            measured[ih] = True
    if not _finite(joints[ih]) and pred is not None:
        joints[ih] = pred[ih]
        conf[ih] = 0.3
    # Torso: midpoint of neck and pelvis centre.
    it = _J["torso"]
    pelvis = 0.5 * (joints[_J["right_hip"]] + joints[_J["left_hip"]])
    joints[it] = 0.5 * (joints[ineck] + pelvis)
    if not _finite(joints[it]) and pred is not None:
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
            gap = ring[child][0] - ring[parent][0]
            dist = math.sqrt(gap.dot(gap))  # np.linalg.norm(gap), without its overhead
            ratio[_J[child]] = dist / max(bone_lengths[_J[child]], 1e-6)
            penalty = min(1.0, abs(ratio[_J[child]] - 1.0) / 0.5)
            conf[_J[child]] *= 1.0 - 0.5 * penalty
    conf = np.where(np.isfinite(joints).all(axis=1), np.clip(conf, 0.0, 1.0), 0.0)
    return SkeletonFit(
        joints=joints,
        confidence=conf,
        measured=measured,
        length_ratio=ratio,
        pelvis_width=placed_width,
    )


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
    ext = np.empty((len(_BONE_ROW), 3))  # the joints, then the pelvis and the limb ends
    ext[: len(_J)] = j
    ext[_BONE_ROW["pelvis"]] = 0.5 * (j[_J["right_hip"]] + j[_J["left_hip"]])
    for side in ("right", "left"):
        el, wr = j[_J[f"{side}_elbow"]], j[_J[f"{side}_hand"]]
        kn, an = j[_J[f"{side}_knee"]], j[_J[f"{side}_foot"]]
        hand_len = 0.74 * bone_lengths[_J[f"{side}_hand"]]
        ext[_BONE_ROW[f"{side}_hand_end"]] = wr + hand_len * _unit(wr - el)
        foot_len = 0.1 * bone_lengths[_J[f"{side}_foot"]]
        ext[_BONE_ROW[f"{side}_foot_end"]] = an + foot_len * _unit(an - kn)
    starts, ends = ext[_BONE_START], ext[_BONE_END]
    t = (np.arange(n) + 0.5) / n
    return starts[:, None, :] + t[None, :, None] * (ends - starts)[:, None, :]


# Rows of bone_anchors' extended joint array: the 15 joints, the pelvis, the hand and foot ends.
_BONE_ROW = {
    **_J,
    **{
        name: len(_J) + k
        for k, name in enumerate(
            ("pelvis", "right_hand_end", "left_hand_end", "right_foot_end", "left_foot_end")
        )
    },
}
# Each part's bone (PART_JOINTS, with the hands and feet ending at the computed ends).
_BONE_ENDS = {"right_hand_tip": "right_hand_end", "left_hand_tip": "left_hand_end"}
_BONE_ENDS.update({"right_toe": "right_foot_end", "left_toe": "left_foot_end"})
_BONE_START = np.array([_BONE_ROW[a] for a, _ in PART_JOINTS])
_BONE_END = np.array([_BONE_ROW[_BONE_ENDS.get(b, b)] for _, b in PART_JOINTS])


# What the votes move: the upper trunk's joints directly, then each upper arm turns
# towards its voted direction (the forearm keeps its own, the hand is carried along).
# The legs keep the labels' skeleton: moving the hips and turning the thighs too made
# the hip and knee angles worse (five point samples of eight clips; docs/results-log.md).
_VOTED_TRUNK = np.array([_J[n] for n in ("neck", "right_shoulder", "left_shoulder")])
_VOTED_ARMS = tuple(
    (_J[f"{side}_shoulder"], _J[f"{side}_elbow"], _J[f"{side}_hand"]) for side in ("right", "left")
)
VOTED_JOINTS = (_J["head"], *(int(j) for j in _VOTED_TRUNK), _J["right_elbow"], _J["left_elbow"])
"""The joints whose votes :func:`refine_with_votes` reads."""


def refine_with_votes(
    joints: np.ndarray,
    voted: np.ndarray,
    *,
    trunk_weight: float = 0.5,
    arm_weight: float = 0.4,
) -> np.ndarray:
    """Move a skeleton towards joints voted by the forest, keeping its arms' lengths.

    The neck and shoulders move ``trunk_weight`` of the way to their voted
    positions; ``torso`` stays the midpoint of neck and pelvis centre, and the
    head follows the neck, its bone turned ``trunk_weight`` of the way towards the
    voted one. Each upper arm then turns ``arm_weight`` of the way towards the
    voted upper arm's direction, from its (moved) shoulder and at its own length;
    the forearm keeps its direction and length. A joint without a vote (NaN in
    ``voted``) is not moved, and a bone missing either voted end keeps its
    direction. The legs are left as they are.

    Parameters
    ----------
    joints : (15, 3) float
        The skeleton (:func:`fit_skeleton`), metres.
    voted : (15, 3) float
        Voted joints (:func:`posedrift.labelling.joint_modes`); NaN rows for none.
    trunk_weight, arm_weight : float
        In [0, 1]; 0 and 0 return ``joints`` unchanged.

    Returns
    -------
    (15, 3) float

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> pose = t_pose_joints(1.75)
    >>> bool(np.allclose(refine_with_votes(pose, pose), pose))
    True
    """
    joints = np.asarray(joints, dtype=float)
    out = joints.copy()
    voted = np.asarray(voted, dtype=float)
    seen = np.isfinite(voted).all(axis=1)
    trunk = _VOTED_TRUNK[seen[_VOTED_TRUNK] & np.isfinite(out[_VOTED_TRUNK]).all(axis=1)]
    out[trunk] += trunk_weight * (voted[trunk] - out[trunk])
    pelvis = 0.5 * (out[_J["right_hip"]] + out[_J["left_hip"]])
    neck, head = _J["neck"], _J["head"]
    if _finite(out[neck]) and _finite(pelvis):
        out[_J["torso"]] = 0.5 * (out[neck] + pelvis)
    _turn_bone(out, joints, voted, seen, neck, head, trunk_weight)
    for shoulder, elbow, hand in _VOTED_ARMS:
        old_elbow = out[elbow].copy()
        _turn_bone(out, joints, voted, seen, shoulder, elbow, arm_weight)
        out[hand] += out[elbow] - old_elbow
    return out


def _turn_bone(out, joints, voted, seen, parent: int, child: int, weight: float) -> None:
    """Re-place ``out[child]`` from ``out[parent]``: the bone of ``joints``, its length
    kept, turned ``weight`` of the way towards the voted bone's direction; in place."""
    bone = joints[child] - joints[parent]
    length = math.sqrt(bone.dot(bone))
    direction = _unit(bone)
    if not (_finite(direction) and _finite(out[parent])):
        return
    if seen[parent] and seen[child]:
        turned = _unit((1.0 - weight) * direction + weight * _unit(voted[child] - voted[parent]))
        direction = turned if _finite(turned) else direction
    out[child] = out[parent] + length * direction
