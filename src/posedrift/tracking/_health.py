"""Is the track still good? Loss detection from the registration and the skeleton fit."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, PART_JOINTS, PART_NAMES

_J = JOINT_INDEX


@dataclass(frozen=True)
class Health:
    """The verdict on one frame's track.

    Attributes
    ----------
    ok : bool
    reason : str
        Why the track was judged lost ("" when ok).
    score : float
        Lower is better: the share of points the skeleton does not explain, plus
        penalties (used to compare a tracked fit with a re-initialized one).
    unexplained : float
        Share of points farther than ``max_distance`` from their own part's bone.
    measured : float
        Share of joints measured from this frame's labels.
    """

    ok: bool
    reason: str
    score: float
    unexplained: float
    measured: float


# Bone ends beyond the 15 joints, as rows of the extended joint array of _segments.
_EXTRA = ("pelvis", "right_hand_tip", "left_hand_tip", "right_toe", "left_toe")
_ROW = {**_J, **{name: len(_J) + k for k, name in enumerate(_EXTRA)}}
_SEG_START = np.array([_ROW[a] for a, _ in PART_JOINTS])
_SEG_END = np.array([_ROW[b] for _, b in PART_JOINTS])
_PELVIS, _RIGHT_HIP, _LEFT_HIP = _ROW["pelvis"], _J["right_hip"], _J["left_hip"]
_TIPS = np.array([_ROW["right_hand_tip"], _ROW["left_hand_tip"]])
_TOES = np.array([_ROW["right_toe"], _ROW["left_toe"]])
_HANDS = np.array([_J["right_hand"], _J["left_hand"]])
_ELBOWS = np.array([_J["right_elbow"], _J["left_elbow"]])
_FEET = np.array([_J["right_foot"], _J["left_foot"]])
_KNEES = np.array([_J["right_knee"], _J["left_knee"]])
# Limb joints checked for floating away from the body (JOINT_INDEX order).
_LIMB_NAMES = tuple(n for n in _J if n.endswith(("elbow", "hand", "knee", "foot")))
_LIMBS = np.array([_J[n] for n in _LIMB_NAMES])


def _segments(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start and end ``(15, 3)`` of each part's bone (hands and feet as short stubs)."""
    j = joints
    ext = np.empty((len(_ROW), 3))
    ext[: len(_J)] = j
    ext[_PELVIS] = 0.5 * (j[_RIGHT_HIP] + j[_LEFT_HIP])
    hands, feet = j[_HANDS], j[_FEET]
    ext[_TIPS] = hands + 0.6 * (hands - j[_ELBOWS])
    ext[_TOES] = feet + 0.15 * (feet - j[_KNEES])
    return ext[_SEG_START], ext[_SEG_END]


def bone_distances(points: np.ndarray, labels: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Distance (metres) from each point to the bone of its own part; NaN where unknown."""
    starts, ends = _segments(np.asarray(joints, dtype=float))
    lab = np.asarray(labels).astype(np.int64, copy=False)
    ok = (lab >= 0) & (lab < len(PART_NAMES))
    out = np.full(len(points), np.nan)
    if not ok.any():
        return out
    if not ok.all():  # (usually all are: no copies)
        points, lab = points[ok], lab[ok]
    a = starts[lab]
    ab = (ends - starts)[lab]  # the same differences as ends[lab] - starts[lab]
    denom = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.where(denom > 0, denom, 1.0), 0, 1)
    gap = points - (a + t[:, None] * ab)
    gap *= gap  # np.linalg.norm(gap, axis=1)'s sums, coordinate by coordinate (cheaper)
    out[ok] = np.sqrt(gap[:, 0] + gap[:, 1] + gap[:, 2])
    return out


def _joint_gaps(points: np.ndarray, joints: np.ndarray) -> np.ndarray:
    """Distance (metres) from each joint ``(K, 3)`` to the nearest point.

    Coordinate by coordinate: the same sums as ``((joints[:, None] - points) ** 2).sum(-1)``
    without the ``(K, N, 3)`` array.
    """
    d2 = (joints[:, 0, None] - points[:, 0]) ** 2
    d2 += (joints[:, 1, None] - points[:, 1]) ** 2
    d2 += (joints[:, 2, None] - points[:, 2]) ** 2
    return np.sqrt(d2.min(axis=1))


# Expected surface distance of each part's points from its bone (metres): torso parts are wide.
_PART_REACH = np.array(
    [0.13, 0.22, 0.2, 0.08, 0.08, 0.07, 0.07, 0.08, 0.08, 0.11, 0.11, 0.08, 0.08, 0.1, 0.1]
)


def unexplained_share(
    points: np.ndarray,
    labels: np.ndarray,
    joints: np.ndarray,
    *,
    height: float,
    slack: float = 0.06,
) -> float:
    """Share of the points farther from their own part's bone than its reach plus ``slack``.

    The reach is each part's expected surface distance from its bone, scaled by
    ``height`` (metres); points with unknown distances count as far. 1.0 for no points.
    """
    dist = bone_distances(points, labels, joints)
    lab = np.asarray(labels).astype(np.int64, copy=False)
    reach = _PART_REACH * (height / 1.75)
    limit = np.where((lab >= 0) & (lab < len(reach)), reach[np.clip(lab, 0, 14)] + slack, 0.0)
    bad = ~np.isfinite(dist) | (dist > limit)
    return float(np.count_nonzero(bad) / len(bad)) if len(bad) else 1.0  # np.mean(bad), cheaper


def assess(
    points: np.ndarray,
    labels: np.ndarray,
    joints: np.ndarray,
    measured: np.ndarray,
    *,
    height: float,
    sigma: float | None = None,
    max_unexplained: float = 0.2,
    max_sigma: float = 0.08,
    min_measured: float = 0.5,
    slack: float = 0.06,
    max_joint_gap: float = 0.15,
    in_view: np.ndarray | None = None,
) -> Health:
    """Judge one frame's registration and skeleton fit.

    Lost when: the skeleton has unknown joints; more than ``max_unexplained`` of
    the points lie farther from their own part's bone than that part's expected
    reach plus ``slack`` (labels that the skeleton does not explain); fewer than
    ``min_measured`` of the joints were measured; or the registration's residual
    ``sigma`` (metres) exceeds ``max_sigma``.

    Parameters
    ----------
    points : (N, 3) float
    labels : (N,) int
    joints : (15, 3) float
    measured : (15,) bool
    height : float
        Stature in metres (scales the expected reach of each part).
    sigma : float, optional
        Registration residual in metres (``sqrt(sigma^2)``).
    max_joint_gap : float
        Largest distance (metres) from a limb joint to the nearest point: a hand
        or foot floating beside the body is lost.
    in_view : (15,) bool, optional
        Joints inside the camera's view; only those are held to ``max_joint_gap``
        (a foot below the image's edge is far from every point and still fine).

    Returns
    -------
    Health
    """
    joints = np.asarray(joints, dtype=float)
    meas = float(np.mean(measured))
    if not np.isfinite(joints).all():
        return Health(False, "the skeleton has unknown joints", np.inf, 1.0, meas)
    unexplained = unexplained_share(points, labels, joints, height=height, slack=slack)
    score = unexplained + 0.5 * (1.0 - meas)
    if sigma is not None and np.isfinite(sigma):
        score += max(0.0, sigma - 0.02)
    if unexplained > max_unexplained:
        return Health(
            False,
            f"{100 * unexplained:.0f}% of the points are far from their part's bone",
            score,
            unexplained,
            meas,
        )
    if meas < min_measured:
        return Health(
            False,
            f"only {100 * meas:.0f}% of the joints are supported by the labels",
            score,
            unexplained,
            meas,
        )
    gaps = _joint_gaps(np.asarray(points, dtype=float), joints[_LIMBS])
    if in_view is not None:
        gaps = np.where(np.asarray(in_view, dtype=bool)[_LIMBS], gaps, 0.0)
    if gaps.max() > max_joint_gap * (height / 1.75):
        worst = _LIMB_NAMES[int(np.argmax(gaps))]
        return Health(
            False,
            f"the {worst} is {100 * gaps.max():.0f} cm from the body",
            score + 0.5,
            unexplained,
            meas,
        )
    if sigma is not None and np.isfinite(sigma) and sigma > max_sigma:
        return Health(
            False, f"the registration residual is {100 * sigma:.1f} cm", score, unexplained, meas
        )
    return Health(True, "", score, unexplained, meas)
