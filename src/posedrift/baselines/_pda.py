"""Dinh et al. 2014, per frame: principal direction analysis of the labelled parts.

Dinh et al., "Principal direction analysis-based real-time 3D human
pose reconstruction from a single depth image", SoICT 2013 / Journal 2014,
doi:10.1145/2542050.2542071.

Every frame on its own: the same per-pixel forest labels as Shotton's baseline,
then each part's principal direction (the first eigenvector of its 3-D points,
:func:`posedrift.skeleton._fit.part_axes`), signed from proximal to distal. The
joint angles follow from the directions of adjacent parts. To report them through
the common :class:`~posedrift.tracking.FrameResult`, the joints are built by
chaining the directions with bone lengths (measured on the first frame by the
tracker's own calibration), so that :attr:`FrameResult.angles` equals the direction angles exactly:

- the trunk's downward axis ``t`` is the principal direction of the torso's
  points (both torso parts), signed from the upper to the lower torso; where the
  torso is not elongated enough it is the direction between the two centroids;
- ``neck`` and the pelvis centre lie on the trunk line through the torso centroids
  (pushed back by the torso's radius), one trunk length apart; hips and shoulders
  sit across that line by the calibrated widths, along the direction between the
  thighs (or the upper arms);
- each limb part's direction ``d`` is signed from proximal to distal: towards
  the part's centroid from the proximal joint (shoulder, hip) or from the
  proximal part's centroid (upper arm, thigh), and on towards the distal part's
  centroid where that part is seen; then
  ``elbow = shoulder + L_upper_arm d``, ``hand = elbow + L_forearm d'``, and
  the same for the legs.

A part with too few points keeps its direction from the previous frame (or hangs
along the trunk on the first frame); the frame still gets a pose, with that
joint's confidence lowered.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from posedrift._validation import check_scalar
from posedrift.baselines._common import calibrate_bones, label_frame, resolve_forest
from posedrift.camera import DepthFrame, Intrinsics
from posedrift.skeleton import JOINT_INDEX, PART_INDEX
from posedrift.tracking import FrameResult, FrameStatus

_J = JOINT_INDEX
_P = PART_INDEX
_TORSO_RADIUS = 0.09
_LIMBS = (
    # (part, proximal joint, distal joint)
    ("right_upper_arm", "right_shoulder", "right_elbow"),
    ("left_upper_arm", "left_shoulder", "left_elbow"),
    ("right_forearm", "right_elbow", "right_hand"),
    ("left_forearm", "left_elbow", "left_hand"),
    ("right_thigh", "right_hip", "right_knee"),
    ("left_thigh", "left_hip", "left_knee"),
    ("right_shank", "right_knee", "right_foot"),
    ("left_shank", "left_knee", "left_foot"),
)
_ROOTED = ("right_shoulder", "left_shoulder", "right_hip", "left_hip")
_PROXIMAL = {
    "right_forearm": "right_upper_arm",
    "left_forearm": "left_upper_arm",
    "right_shank": "right_thigh",
    "left_shank": "left_thigh",
}
_DISTAL = {
    "right_upper_arm": "right_forearm",
    "left_upper_arm": "left_forearm",
    "right_forearm": "right_hand",
    "left_forearm": "left_hand",
    "right_thigh": "right_shank",
    "left_thigh": "left_shank",
    "right_shank": "right_foot",
    "left_shank": "left_foot",
}


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else np.full(3, np.nan)


def pda_skeleton(
    points: np.ndarray,
    labels: np.ndarray,
    *,
    bone_lengths: np.ndarray,
    min_points: int = 10,
    previous: dict[str, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, np.ndarray]]:
    """Joints from the principal directions of labelled parts.

    Parameters
    ----------
    points : (N, 3) float
        Camera frame, metres.
    labels : (N,) int
        Part per point (-1 unlabelled).
    bone_lengths : (15,) float
        ``|joint - parent|`` in metres (``JOINT_PARENTS``), e.g. from calibration.
    min_points : int
        Fewest points for a part's direction.
    previous : dict, optional
        Directions of the previous frame (``{part_name: (3,)}``), used for parts
        with too few points.

    Returns
    -------
    joints : (15, 3) float
        NaN everywhere when the torso is not seen.
    confidence : (15,) float
    directions : dict of part name -> (3,) unit vector
        ``"trunk"`` and the eight limb parts (for the next frame).

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.skeleton import joint_angles
    >>> rng = np.random.default_rng(0)
    >>> pts = np.concatenate([rng.normal([0, y, 3], 0.01, (50, 3)) for y in (-0.3, 0.0)])
    >>> from posedrift.skeleton._fit import prior_bone_lengths
    >>> bones = prior_bone_lengths(1.75)
    >>> joints, conf, _ = pda_skeleton(pts, np.repeat([1, 2], 50), bone_lengths=bones)
    >>> np.round(joint_angles(joints)[[0, 2]], 0)  # unseen arms hang along the trunk
    array([180.,   0.])
    """
    points = np.asarray(points, dtype=float)
    labels = np.asarray(labels).astype(np.int64)
    from posedrift.skeleton._fit import part_axes

    previous = previous or {}
    bones = np.asarray(bone_lengths, dtype=float)
    joints = np.full((15, 3), np.nan)
    conf = np.zeros(15)
    counts = np.bincount(labels[labels >= 0], minlength=15)
    cent = np.full((15, 3), np.nan)
    for p in np.nonzero(counts)[0]:
        cent[p] = points[labels == p].mean(axis=0)
    axes, elong = part_axes(points, labels, min_points=min_points)
    ut, lt = _P["upper_torso"], _P["lower_torso"]
    torso = (labels == ut) | (labels == lt)
    if counts[ut] < min_points or counts[lt] < min_points:
        return joints, conf, dict(previous)

    # Trunk: principal direction of the torso's points, signed upper -> lower.
    between = _unit(cent[lt] - cent[ut])
    tp = points[torso]
    w, v = np.linalg.eigh(np.cov((tp - tp.mean(axis=0)).T))
    trunk = v[:, 2] if w[2] > 1.5 * w[1] else between
    trunk = trunk if trunk @ between >= 0 else -trunk
    centre = 0.5 * (cent[ut] + cent[lt])
    centre = centre + _TORSO_RADIUS * _unit(centre)
    trunk_length = 2.0 * bones[_J["neck"]]
    neck = centre - 0.5 * trunk_length * trunk
    pelvis = centre + 0.5 * trunk_length * trunk

    # Across the body (person's right to left), orthogonal to the trunk.
    across = np.full(3, np.nan)
    for a, b in (("right_thigh", "left_thigh"), ("right_upper_arm", "left_upper_arm")):
        if counts[_P[a]] >= min_points and counts[_P[b]] >= min_points:
            across = cent[_P[b]] - cent[_P[a]]
            break
    if not np.isfinite(across).all():
        across = previous.get("across", np.array([1.0, 0.0, 0.0]))
    across = _unit(across - (across @ trunk) * trunk)
    half_hip = np.sqrt(max(bones[_J["right_hip"]] ** 2 - bones[_J["neck"]] ** 2, 0.0))
    joints[_J["neck"]] = neck
    joints[_J["right_shoulder"]] = neck - bones[_J["right_shoulder"]] * across
    joints[_J["left_shoulder"]] = neck + bones[_J["left_shoulder"]] * across
    joints[_J["right_hip"]] = pelvis - half_hip * across
    joints[_J["left_hip"]] = pelvis + half_hip * across
    joints[_J["torso"]] = 0.5 * (neck + pelvis)
    for name in ("neck", "right_shoulder", "left_shoulder", "right_hip", "left_hip", "torso"):
        conf[_J[name]] = 1.0
    head = _P["head"]
    up = -trunk
    if counts[head] >= min_points:
        to_head = _unit(cent[head] + 0.07 * _unit(cent[head]) - neck)
        if np.isfinite(to_head).all():
            up = to_head
    joints[_J["head"]] = neck + bones[_J["head"]] * up
    conf[_J["head"]] = 1.0 if counts[head] >= min_points else 0.3

    directions: dict[str, np.ndarray] = {"trunk": trunk, "across": across}
    for part_name, prox, dist in _LIMBS:
        p = _P[part_name]
        start = joints[_J[prox]]
        d = axes[p]
        if counts[p] >= min_points and np.isfinite(d).all():
            # Proximal to distal: from the proximal joint (shoulder, hip) or the proximal
            # part's centroid (elbow, knee) towards this part's centroid, and on towards
            # the distal part's centroid where it is seen.
            before = start if prox in _ROOTED else cent[_P[_PROXIMAL[part_name]]]
            if not np.isfinite(before).all():
                before = start
            toward = cent[p] - before
            after = _DISTAL.get(part_name)
            if after is not None and counts[_P[after]] >= min_points:
                toward = _unit(toward) + _unit(cent[_P[after]] - cent[p])
            if elong[p] < 2.0:  # a blob (a foreshortened limb): the centroid's direction
                d = _unit(cent[p] - start)
            elif d @ toward < 0:
                d = -d
            c = 1.0
        else:
            d = previous.get(part_name, trunk)
            c = 0.3
        directions[part_name] = d
        joints[_J[dist]] = start + bones[_J[dist]] * d
        conf[_J[dist]] = c * conf[_J[prox]]
    return joints, conf, directions


class PDABaseline:
    """Dinh et al. 2014 per frame (a :class:`posedrift.tracking.PoseMethod`).

    Parameters
    ----------
    intrinsics : Intrinsics
    forest : BodyPartForest, optional
        The shared body-part forest (the default model when None).
    threshold : float
        Pixels whose most probable part is below this probability stay unlabelled.
        0.4 was best of 0.1, 0.14, 0.25, 0.4 on the development clips 002_05 and
        002_08 (18.7 against 20.6 degrees at 0.14): uncertain pixels bend the axes.
    min_points : int
        Fewest pixels for a part's principal direction.
    stride : int
        Keep every ``stride``-th labelled pixel in the returned points.
    """

    name = "pda"

    def __init__(
        self,
        intrinsics: Intrinsics,
        *,
        forest: Any = None,
        threshold: float = 0.4,
        min_points: int = 10,
        stride: int = 4,
    ) -> None:
        self.intrinsics = intrinsics
        self.forest = resolve_forest(forest)
        self.threshold = check_scalar(
            threshold, "threshold", low=0.0, high=1.0, include_low=True, caller="PDABaseline"
        )
        self.min_points = int(
            check_scalar(min_points, "min_points", low=1, include_low=True, integer=True)
        )
        self.stride = int(check_scalar(stride, "stride", low=1, include_low=True, integer=True))
        self.stature_: float | None = None
        self.bone_lengths_: np.ndarray | None = None
        self._directions: dict[str, np.ndarray] = {}

    def reset(self, intrinsics: Intrinsics) -> None:
        """Forget the stature and the last directions."""
        self.intrinsics = intrinsics
        self.stature_ = None
        self.bone_lengths_ = None
        self._directions = {}

    def process(self, frame: DepthFrame) -> FrameResult:
        """Joints of one frame from its parts' principal directions."""
        start = time.perf_counter()
        lab = label_frame(frame, self.forest, threshold=self.threshold)
        t_label = time.perf_counter()
        if lab is None:
            return FrameResult.empty(
                frame.index, FrameStatus.NO_PERSON, "no person found", timestamp=frame.timestamp
            )
        if self.bone_lengths_ is None:
            self.stature_, self.bone_lengths_ = calibrate_bones(lab, frame.depth.shape[0])
        joints, conf, directions = pda_skeleton(
            lab.points,
            lab.labels,
            bone_lengths=self.bone_lengths_,
            min_points=self.min_points,
            previous=self._directions,
        )
        self._directions = directions
        end = time.perf_counter()
        keep = slice(None, None, self.stride)
        labelled = lab.labels[keep] >= 0
        ok = np.isfinite(joints).all()
        return FrameResult(
            index=frame.index,
            status=FrameStatus.REINITIALIZED if ok else FrameStatus.LOST,
            joints=joints,
            confidence=conf,
            points=lab.points[keep][labelled],
            labels=lab.labels[keep][labelled],
            timestamp=frame.timestamp,
            timings_ms={"labels": 1000 * (t_label - start), "skeleton": 1000 * (end - t_label)},
            message="" if ok else "the torso is not labelled",
        )
