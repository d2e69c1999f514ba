"""A scripted, smooth motion that needs no external data: the built-in demo sequence.

The body is the 15-joint skeleton of :func:`~posedrift.skeleton.t_pose_joints` (bone
lengths from ``SEGMENT_RATIOS``) with extras (head top, hand tips, toes). A pose is a
set of segment directions in body frames:

- the trunk (neck, shoulders, torso, hips, head) is rigid and turns about the pelvis
  centre by ``yaw`` (about +Y) then ``bend`` (forward pitch about the hip axis);
- each arm segment points along ``(elevation, azimuth)`` in the trunk frame:
  elevation is the angle from straight down (the shoulder angle of Table 1 for the
  upper arm), azimuth 0 is straight out to the side, 90 forward, 180 across the body;
- each leg segment points along ``(flexion, abduction)`` in the yawed pelvis frame:
  straight down turned forward by the flexion (negative: backward), then outward by
  the abduction (negative: across the body), so that interpolating from standing
  never swings a leg sideways;
- hand tips continue the forearm; the head top sits above the head on the trunk axis;
  the toes lie flat forward and tilt with the shank once the foot leaves the floor.

Keyframes are interpolated with a cosine ease (C1: zero velocity at each key). The
pelvis moves so that the feet stay put: vertically, the lower ankle stands at the
ankle height; horizontally, each foot that bears weight (the lower one, softly
weighted) keeps its standing place, so feet do not slide during arm moves, the
squat and the bend.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from posedrift._validation import check_scalar
from posedrift.skeleton import JOINT_INDEX, JOINT_NAMES, SEGMENT_RATIOS, t_pose_joints
from posedrift.synthetic._motion import Motion

_J = JOINT_INDEX
_LIMBS = ("l_arm", "r_arm", "l_leg", "r_leg")


@dataclass(frozen=True)
class _Pose:
    """Keyframe parameters, degrees: each limb (upper e, upper a, lower e, lower a)."""

    l_arm: tuple[float, float, float, float] = (90.0, 0.0, 90.0, 0.0)
    r_arm: tuple[float, float, float, float] = (90.0, 0.0, 90.0, 0.0)
    l_leg: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    r_leg: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)
    bend: float = 0.0
    yaw: float = 0.0
    extra: dict = field(default_factory=dict)

    def vector(self) -> np.ndarray:
        return np.array([*self.l_arm, *self.r_arm, *self.l_leg, *self.r_leg, self.bend, self.yaw])


_T = _Pose()
_DOWN = (8.0, 0.0, 8.0, 10.0)
_STAND = _Pose(l_arm=_DOWN, r_arm=_DOWN)


def _script(turn: float) -> list[tuple[float, _Pose]]:
    """One cycle of (duration to reach, pose) steps after the opening T-pose.

    ``turn`` is the yaw (degrees) the cycle starts from.
    """
    y = turn

    def p(**kw: object) -> _Pose:
        base = {"l_arm": _DOWN, "r_arm": _DOWN, "yaw": y}
        base.update(kw)
        return _Pose(**base)  # type: ignore[arg-type]

    up = (170.0, 0.0, 172.0, 0.0)
    forward = (90.0, 90.0, 90.0, 90.0)
    side = (90.0, 0.0, 90.0, 0.0)
    # Arms crossed in front of the chest: upper arms forward and in, forearms across;
    # the left forearm passes above the right.
    cross_l = (75.0, 125.0, 100.0, 172.0)
    cross_r = (62.0, 120.0, 80.0, 178.0)
    curl = (10.0, 90.0, 125.0, 90.0)
    return [
        (0.8, p()),  # arms down
        (0.4, p()),
        (1.5, p(l_arm=up, r_arm=up)),  # both arms up over the head, through the sides
        (0.4, p(l_arm=up, r_arm=up)),
        (1.5, p()),
        (1.2, p(l_arm=forward, r_arm=side)),  # left arm forward, right arm sideways
        (1.2, p(l_arm=side, r_arm=forward)),
        (1.0, p()),
        (1.5, p(l_arm=cross_l, r_arm=cross_r)),  # arms cross in front of the chest
        (0.6, p(l_arm=cross_l, r_arm=cross_r)),
        (1.2, p()),
        (1.0, p(l_arm=curl, r_arm=curl)),  # elbow curls
        (1.0, p()),
        # right leg crosses in front of the left, arms out for balance
        (
            1.4,
            p(
                l_arm=(45.0, 0.0, 45.0, 0.0),
                r_arm=(45.0, 0.0, 45.0, 0.0),
                r_leg=(25.0, -20.0, 22.0, -20.0),
            ),
        ),
        (
            0.6,
            p(
                l_arm=(45.0, 0.0, 45.0, 0.0),
                r_arm=(45.0, 0.0, 45.0, 0.0),
                r_leg=(25.0, -20.0, 22.0, -20.0),
            ),
        ),
        (1.2, p()),
        # left front kick: knee up, then the shank snaps out, then back
        (
            0.7,
            p(
                l_arm=(35.0, 0.0, 35.0, 0.0),
                r_arm=(35.0, 0.0, 35.0, 0.0),
                l_leg=(70.0, 0.0, -10.0, 0.0),
            ),
        ),
        (
            0.4,
            p(
                l_arm=(35.0, 0.0, 35.0, 0.0),
                r_arm=(35.0, 0.0, 35.0, 0.0),
                l_leg=(80.0, 0.0, 75.0, 0.0),
            ),
        ),
        (0.8, p()),
        # right side kick
        (
            0.7,
            p(
                l_arm=(40.0, 0.0, 40.0, 0.0),
                r_arm=(40.0, 0.0, 40.0, 0.0),
                r_leg=(10.0, 55.0, -5.0, 15.0),
            ),
        ),
        (
            0.4,
            p(
                l_arm=(40.0, 0.0, 40.0, 0.0),
                r_arm=(40.0, 0.0, 40.0, 0.0),
                r_leg=(5.0, 65.0, 0.0, 60.0),
            ),
        ),
        (0.8, p()),
        # squat with the arms forward
        (
            1.4,
            p(
                l_arm=forward,
                r_arm=forward,
                l_leg=(78.0, 0.0, -28.0, 0.0),
                r_leg=(78.0, 0.0, -28.0, 0.0),
                bend=35.0,
            ),
        ),
        (
            0.6,
            p(
                l_arm=forward,
                r_arm=forward,
                l_leg=(78.0, 0.0, -28.0, 0.0),
                r_leg=(78.0, 0.0, -28.0, 0.0),
                bend=35.0,
            ),
        ),
        (1.4, p()),
        # bend forward, reaching down
        (1.4, p(l_arm=(80.0, 90.0, 85.0, 90.0), r_arm=(80.0, 90.0, 85.0, 90.0), bend=70.0)),
        (0.5, p(l_arm=(80.0, 90.0, 85.0, 90.0), r_arm=(80.0, 90.0, 85.0, 90.0), bend=70.0)),
        (1.4, p()),
        # quarter turn to the left, arms half out
        (1.8, p(l_arm=(30.0, 0.0, 30.0, 0.0), r_arm=(30.0, 0.0, 30.0, 0.0), yaw=y + 90.0)),
        (0.8, p(yaw=y + 90.0)),
    ]


def _keyframes(seconds: float) -> tuple[np.ndarray, np.ndarray]:
    """Key times and pose vectors: a 1 s T-pose hold, then cycles of the script."""
    times, poses = [0.0, 1.0], [_T.vector(), _T.vector()]
    turn = 0.0
    while times[-1] < seconds:
        for duration, pose in _script(turn):
            times.append(times[-1] + duration)
            poses.append(pose.vector())
        turn += 90.0
    return np.array(times), np.array(poses)


SCRIPT_SECONDS = float(sum(d for d, _ in _script(0.0)) + 1.0)
"""Length of one full script, seconds (the default length of the motion)."""


def _ease(times: np.ndarray, keys: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Cosine-eased interpolation between keyframes, ``(n, P)``."""
    k = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 2)
    span = keys[k + 1] - keys[k]
    u = np.clip((times - keys[k]) / span, 0.0, 1.0)
    s = 0.5 - 0.5 * np.cos(np.pi * u)
    return values[k] * (1 - s[:, None]) + values[k + 1] * s[:, None]


def _leg_direction(flex: np.ndarray, abd: np.ndarray, side: float) -> np.ndarray:
    """Unit vectors ``(n, 3)``: down turned forward by ``flex`` then outward by ``abd``."""
    f, b = np.radians(flex), np.radians(abd)
    return np.stack([side * np.cos(f) * np.sin(b), -np.cos(f) * np.cos(b), np.sin(f)], axis=-1)


def _direction(e: np.ndarray, a: np.ndarray, side: float) -> np.ndarray:
    """Unit vectors ``(n, 3)`` in a body frame (x left, y up, z forward)."""
    e, a = np.radians(e), np.radians(a)
    return np.stack([side * np.sin(e) * np.cos(a), -np.cos(e), np.sin(e) * np.sin(a)], axis=-1)


def _rot_y(deg: np.ndarray) -> np.ndarray:
    t = np.radians(deg)
    c, s = np.cos(t), np.sin(t)
    z, o = np.zeros_like(t), np.ones_like(t)
    return np.stack([np.stack([c, z, s], -1), np.stack([z, o, z], -1), np.stack([-s, z, c], -1)], 1)


def _rot_x(deg: np.ndarray) -> np.ndarray:
    t = np.radians(deg)
    c, s = np.cos(t), np.sin(t)
    z, o = np.zeros_like(t), np.ones_like(t)
    return np.stack([np.stack([o, z, z], -1), np.stack([z, c, -s], -1), np.stack([z, s, c], -1)], 1)


def procedural_motion(
    *, height: float = 1.75, fps: float = 30.0, seconds: float | None = None
) -> Motion:
    """A scripted, smooth whole-body motion, deterministic and data-free.

    Frame 0 is a T-pose held for one second; then arms down, both arms raised over the
    head, one arm forward and the other sideways, arms crossing in front of the chest,
    elbow curls, a leg crossing in front of the other, a front kick, a side kick, a
    squat, a forward bend, and a quarter turn to the left. Longer ``seconds`` repeat
    the script, each repeat a quarter turn further round.

    Parameters
    ----------
    height : float
        Stature in metres (segment lengths from ``SEGMENT_RATIOS``).
    fps : float
        Frames per second.
    seconds : float, optional
        Length; :data:`SCRIPT_SECONDS` (one pass of the script) by default.

    Returns
    -------
    Motion
        World frame: +Y up, floor y = 0, pelvis at x = z = 0 facing +Z at frame 0;
        extras ``head_top``, hand tips and toes.

    Examples
    --------
    >>> m = procedural_motion(seconds=1.0)
    >>> len(m), m.fps
    (31, 30.0)
    >>> np.round(m.angles[0], 1)
    array([180., 180.,  90.,  90., 180., 180.,   0.,   0.])
    """
    height = check_scalar(height, "height", low=0.0, caller="procedural_motion")
    fps = check_scalar(fps, "fps", low=0.0, caller="procedural_motion")
    if seconds is None:
        seconds = SCRIPT_SECONDS
    seconds = check_scalar(seconds, "seconds", low=0.0, caller="procedural_motion")
    r = SEGMENT_RATIOS
    h = height
    n = int(np.floor(seconds * fps + 1e-6)) + 1
    times = np.arange(n) / fps
    keys, values = _keyframes(seconds)
    v = _ease(times, keys, values)
    limb = {name: v[:, 4 * i : 4 * i + 4] for i, name in enumerate(_LIMBS)}
    bend, yaw = v[:, 16], v[:, 17]

    rest = t_pose_joints(h)
    pelvis_rest = 0.5 * (rest[_J["left_hip"]] + rest[_J["right_hip"]])
    yaw_m = _rot_y(yaw)
    trunk = yaw_m @ _rot_x(bend)  # pitch forward about the hip axis (+X): +Y -> +Z
    joints = np.zeros((n, len(JOINT_NAMES), 3))
    for name in (
        "neck",
        "head",
        "right_shoulder",
        "left_shoulder",
        "torso",
        "right_hip",
        "left_hip",
    ):
        local = rest[_J[name]] - pelvis_rest
        if name.endswith("_hip"):
            joints[:, _J[name]] = yaw_m @ local
        else:
            joints[:, _J[name]] = trunk @ local
    extras = {"head_top": trunk @ np.array([0.0, h - pelvis_rest[1], 0.0])}
    seg = {
        "arm": (r["upper_arm"] * h, r["forearm"] * h),
        "leg": (r["thigh"] * h, r["shank"] * h),
    }
    for side_name, side in (("left", 1.0), ("right", -1.0)):
        for kind, frame, (j1, j2, j3) in (
            ("arm", trunk, ("shoulder", "elbow", "hand")),
            ("leg", yaw_m, ("hip", "knee", "foot")),
        ):
            p = limb[f"{side_name[0]}_{kind}"]
            direction = _direction if kind == "arm" else _leg_direction
            d1 = np.einsum("tij,tj->ti", frame, direction(p[:, 0], p[:, 1], side))
            d2 = np.einsum("tij,tj->ti", frame, direction(p[:, 2], p[:, 3], side))
            root = joints[:, _J[f"{side_name}_{j1}"]]
            joints[:, _J[f"{side_name}_{j2}"]] = root + seg[kind][0] * d1
            joints[:, _J[f"{side_name}_{j3}"]] = (
                joints[:, _J[f"{side_name}_{j2}"]] + seg[kind][1] * d2
            )
            if kind == "arm":
                extras[f"{side_name}_hand_tip"] = (
                    joints[:, _J[f"{side_name}_hand"]] + r["hand"] * h * d2
                )
    # Feet: vertical placement, then the weight-bearing feet keep their places.
    ankle_h = r["ankle_height"] * h
    feet = joints[:, [_J["left_foot"], _J["right_foot"]]]
    lift = ankle_h - feet[:, :, 1].min(axis=1)
    joints[:, :, 1] += lift[:, None]
    for k in extras:
        extras[k] = extras[k] + np.array([0.0, 1.0, 0.0]) * lift[:, None]
    feet = joints[:, [_J["left_foot"], _J["right_foot"]]]
    rest_feet = np.stack(
        [yaw_m @ (rest[_J[f"{s}_foot"]] - pelvis_rest) for s in ("left", "right")], axis=1
    )
    height_above = feet[:, :, 1] - feet[:, :, 1].min(axis=1, keepdims=True)
    weight = np.exp(-height_above / 0.003)
    weight /= weight.sum(axis=1, keepdims=True)
    slip = np.einsum("tf,tfc->tc", weight, rest_feet - feet)
    slip[:, 1] = 0.0
    joints += slip[:, None, :]
    for k in extras:
        extras[k] = extras[k] + slip
    # Toes: flat forward on the floor; tilting with the shank when the foot is lifted.
    toe_len = np.hypot(0.75 * r["foot_length"] * h, ankle_h)
    for s in ("left", "right"):
        ankle = joints[:, _J[f"{s}_foot"]]
        fwd = np.einsum("tij,j->ti", yaw_m, [0.0, 0.0, 1.0])
        flat = (0.75 * r["foot_length"] * h * fwd - ankle_h * np.array([0.0, 1.0, 0.0])) / toe_len
        p = limb[f"{s[0]}_leg"]
        sh = np.einsum(
            "tij,tj->ti", yaw_m, _leg_direction(p[:, 2], p[:, 3], 1.0 if s == "left" else -1.0)
        )
        # The flat foot turned with the shank away from vertical.
        down = np.array([0.0, -1.0, 0.0])
        tilted = _turn_like(flat, down, sh)
        lifted = np.clip((ankle[:, 1] - ankle_h) / 0.05, 0.0, 1.0)[:, None]
        toe_dir = (1 - lifted) * flat + lifted * tilted
        toe_dir /= np.linalg.norm(toe_dir, axis=1, keepdims=True)
        extras[f"{s}_toe"] = ankle + toe_len * toe_dir
    joints[:, _J["torso"]] = 0.5 * (
        joints[:, _J["neck"]] + 0.5 * (joints[:, _J["left_hip"]] + joints[:, _J["right_hip"]])
    )
    return Motion(joints, extras, fps, "procedural", {"source": "procedural", "stature_m": height})


def _turn_like(v: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotate vectors ``v`` (n, 3) by the rotation taking unit ``a`` (3,) onto ``b`` (n, 3)."""
    axis = np.cross(a, b)
    s = np.linalg.norm(axis, axis=1, keepdims=True)
    c = (b @ a)[:, None]
    k = np.where(s > 1e-9, axis / np.where(s > 1e-9, s, 1.0), 0.0)
    # Rodrigues: v cos + (k x v) sin + k (k . v)(1 - cos)
    return v * c + np.cross(k, v) * s + k * np.sum(k * v, axis=1, keepdims=True) * (1 - c)
