"""A humanoid-shaped point set: area-uniform samples on a capsule body posed by 15 joints.

Used as test and benchmark data for registration (a stand-in for the downsampled depth
points of a person) and by other developers' tests. Not a body model: for rendered,
realistic bodies see ``posedrift.synthetic``.
"""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_points, check_rng, check_scalar
from posedrift.skeleton._definitions import JOINT_INDEX

# (start joint, end joint or None for a sphere, radius as a fraction of stature H).
# Radii are rough anthropometric half-widths (head breadth ~0.13 H, thigh ~0.12 H, ...).
_J = JOINT_INDEX
_CAPSULES: tuple[tuple[str, str | None, float], ...] = (
    ("head", None, 0.062),
    ("neck", "head", 0.035),
    ("right_shoulder", "left_shoulder", 0.05),
    ("neck", "pelvis", 0.085),
    ("right_shoulder", "right_hip", 0.06),
    ("left_shoulder", "left_hip", 0.06),
    ("right_hip", "left_hip", 0.065),
    ("right_shoulder", "right_elbow", 0.035),
    ("left_shoulder", "left_elbow", 0.035),
    ("right_elbow", "right_hand", 0.028),
    ("left_elbow", "left_hand", 0.028),
    ("right_hand", "right_hand_tip", 0.024),
    ("left_hand", "left_hand_tip", 0.024),
    ("right_hip", "right_knee", 0.055),
    ("left_hip", "left_knee", 0.055),
    ("right_knee", "right_foot", 0.04),
    ("left_knee", "left_foot", 0.04),
    ("right_foot", "right_toe", 0.026),
    ("left_foot", "left_toe", 0.026),
)
_TORSO_FRACTION = 0.308  # |neck - pelvis| / H for the project's T-pose proportions


def _key_points(joints: np.ndarray) -> tuple[dict[str, np.ndarray], float]:
    """Joints plus pelvis, hand tips and toes, and the stature estimated from the trunk."""
    pts = {name: joints[i] for name, i in _J.items()}
    pelvis = 0.5 * (pts["right_hip"] + pts["left_hip"])
    pts["pelvis"] = pelvis
    trunk = pts["neck"] - pelvis
    height = float(np.linalg.norm(trunk)) / _TORSO_FRACTION
    if height <= 0.0:
        raise ValueError(
            "The 'joints' argument of sample_humanoid must have distinct neck and hips. "
            "Got a zero-length trunk instead."
        )
    up = trunk / np.linalg.norm(trunk)
    across = pts["left_hip"] - pts["right_hip"]
    forward = np.cross(across, up)
    nf = np.linalg.norm(forward)
    forward = forward / nf if nf > 0 else np.array([0.0, 0.0, 1.0])
    for side in ("right", "left"):
        arm = pts[f"{side}_hand"] - pts[f"{side}_elbow"]
        na = np.linalg.norm(arm)
        arm = arm / na if na > 0 else -up
        pts[f"{side}_hand_tip"] = pts[f"{side}_hand"] + 0.09 * height * arm
        pts[f"{side}_toe"] = pts[f"{side}_foot"] + 0.11 * height * forward - 0.02 * height * up
    return pts, height


def _capsule_area(length: float, radius: float) -> float:
    return 2.0 * np.pi * radius * length + 4.0 * np.pi * radius**2


def _sample_capsule(
    a: np.ndarray, b: np.ndarray, radius: float, n: int, rng: np.random.Generator
) -> np.ndarray:
    """``n`` area-uniform points on the surface of the capsule from ``a`` to ``b``."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    out = np.empty((n, 3))
    if n == 0:
        return out
    side_area = 2.0 * np.pi * radius * length
    on_side = rng.random(n) < side_area / _capsule_area(length, radius)
    k = int(on_side.sum())
    if k:
        u = axis / length
        helper = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        e1 = np.cross(u, helper)
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(u, e1)
        t = rng.random(k)[:, None] * length
        phi = rng.random(k) * 2.0 * np.pi
        ring = np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
        out[on_side] = a + t * u + radius * ring
    caps = ~on_side
    k = int(caps.sum())
    if k:
        d = rng.normal(size=(k, 3))
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        if length > 0:
            u = axis / length
            along = d @ u
            at_b = rng.random(k) < 0.5
            # hemisphere facing away from the capsule's middle at each end
            d = np.where((at_b & (along < 0))[:, None] | (~at_b & (along > 0))[:, None], -d, d)
            centre = np.where(at_b[:, None], b, a)
        else:
            centre = np.broadcast_to(a, (k, 3))
        out[caps] = centre + radius * d
    return out


def _inside_other(points: np.ndarray, segs: list[tuple[np.ndarray, np.ndarray, float]], own: int):
    """Whether each point lies strictly inside any capsule other than ``own``."""
    inside = np.zeros(len(points), dtype=bool)
    for j, (a, b, r) in enumerate(segs):
        if j == own:
            continue
        ab = b - a
        denom = float(ab @ ab)
        t = np.zeros(len(points)) if denom == 0 else np.clip((points - a) @ ab / denom, 0.0, 1.0)
        dist = np.linalg.norm(points - (a + t[:, None] * ab), axis=1)
        inside |= dist < 0.98 * r
    return inside


def sample_humanoid(
    joints,
    n_points: int,
    *,
    rng: int | np.random.Generator | None = None,
    front_facing: bool = False,
    view_direction=(0.0, 0.0, 1.0),
) -> np.ndarray:
    """Area-uniform surface samples of a capsule body posed by 15 joints.

    The body is a head sphere and capsules for the neck, trunk, hips, limbs, hands
    and feet, with radii proportional to the stature (estimated from the trunk
    length). Surface inside another capsule is dropped, so the points lie on the
    outer skin.

    Parameters
    ----------
    joints : (15, 3) float
        Joint positions in metres, ``skeleton.JOINT_NAMES`` order (any frame).
    n_points : int
        Number of points to return (>= 1).
    rng : int, numpy.random.Generator or None
        Random source.
    front_facing : bool
        Keep only surface whose outward normal points against ``view_direction``
        (what a depth camera looking along ``view_direction`` sees, ignoring
        occlusion).
    view_direction : (3,) float
        Direction from the camera towards the body, used when ``front_facing``.
        The default (0, 0, 1) suits the camera frame (+Z forward).

    Returns
    -------
    points : (n_points, 3) float
        Metres, in the frame of ``joints``.

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> pts = sample_humanoid(t_pose_joints(1.75), 400, rng=0)
    >>> pts.shape
    (400, 3)
    >>> bool(pts[:, 1].max() < 1.8)
    True
    """
    joints = check_points(joints, "joints", dim=3, min_points=15, caller="sample_humanoid")
    if joints.shape[0] != 15:
        raise ValueError(
            "The 'joints' argument of sample_humanoid must have shape (15, 3). "
            f"Got shape {joints.shape} instead."
        )
    n_points = int(
        check_scalar(
            n_points, "n_points", low=1, include_low=True, integer=True, caller="sample_humanoid"
        )
    )
    rng = check_rng(rng)
    view = np.asarray(view_direction, dtype=float).reshape(-1)
    if view.shape != (3,) or not np.all(np.isfinite(view)) or not np.any(view):
        raise ValueError(
            "The 'view_direction' argument of sample_humanoid must be a non-zero finite "
            f"3-vector. Got {view_direction!r} instead."
        )
    view = view / np.linalg.norm(view)
    pts, height = _key_points(joints)
    segs = []
    for start, end, frac in _CAPSULES:
        a = pts[start]
        b = a if end is None else pts[end]
        segs.append((a, b, frac * height))
    areas = np.array([_capsule_area(float(np.linalg.norm(b - a)), r) for a, b, r in segs])
    share = areas / areas.sum()
    kept: list[np.ndarray] = []
    total = 0
    # Oversample, drop hidden (interior or back-facing) samples, repeat until enough.
    for _ in range(50):
        want = max(64, int(2.5 * (n_points - total)) * (2 if front_facing else 1))
        counts = rng.multinomial(want, share)
        for j, (a, b, r) in enumerate(segs):
            p = _sample_capsule(a, b, r, int(counts[j]), rng)
            p = p[~_inside_other(p, segs, j)]
            if front_facing and len(p):
                ab = b - a
                denom = float(ab @ ab)
                t = np.zeros(len(p)) if denom == 0 else np.clip((p - a) @ ab / denom, 0, 1)
                normal = p - (a + t[:, None] * ab)
                p = p[normal @ view < 0]
            kept.append(p)
            total += len(p)
        if total >= n_points:
            break
    allpts = np.concatenate(kept)
    pick = rng.choice(len(allpts), size=n_points, replace=False)
    return allpts[pick]
