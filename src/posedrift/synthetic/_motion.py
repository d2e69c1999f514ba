"""Motions on the 15-joint skeleton: from BVH files, resampled, with a calibration T-pose.

World frame (``INTERFACES.md``): metres, +Y up, floor at y = 0, the pelvis centre at
x = z = 0 and the person facing +Z at frame 0 (so the person's left is +X). All frames
share the one transform: a walking person leaves the origin as in the clip.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from types import MappingProxyType

import numpy as np

from posedrift._validation import check_scalar
from posedrift.skeleton import EXTRA_POINT_NAMES, JOINT_INDEX, JOINT_NAMES, joint_angles
from posedrift.synthetic._bvh import load_bvh
from posedrift.synthetic._rigs import (
    RigMap,
    detect_units,
    detect_up_axis,
    map_positions,
    resolve_rig,
    stature_estimate,
)

_J = JOINT_INDEX

MAX_JOINT_SPEED = 20.0
"""m/s: a leading frame from which some joint would move faster than this to the next
is taken as a detached rest pose and dropped by :func:`bvh_motion`."""


@dataclass(frozen=True, eq=False)
class Motion:
    """A motion on the 15-joint skeleton in the world frame.

    Parameters
    ----------
    joints : (T, 15, 3) float
        Joint positions, metres, world frame (+Y up, floor y = 0), in
        :data:`~posedrift.skeleton.JOINT_NAMES` order.
    extras : mapping of str to (T, 3) float
        Extra points (:data:`~posedrift.skeleton.EXTRA_POINT_NAMES`) the source gives.
    fps : float
        Frames per second.
    name : str
        A label (the file stem for BVH clips).
    meta : mapping
        Provenance (rig, detected units and up axis...), informational only.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.skeleton import t_pose_joints
    >>> m = Motion(np.stack([t_pose_joints(1.75)] * 3), {}, 30.0, "still")
    >>> len(m), m.angles.shape
    (3, (3, 8))
    """

    joints: np.ndarray
    extras: Mapping[str, np.ndarray] = field(default_factory=dict)
    fps: float = 30.0
    name: str = "motion"
    meta: Mapping[str, object] = field(default_factory=dict)

    def __post_init__(self) -> None:
        joints = np.array(self.joints, dtype=float)
        if joints.ndim != 3 or joints.shape[1:] != (len(JOINT_NAMES), 3) or len(joints) < 1:
            raise ValueError(
                f"The 'joints' argument of Motion must have shape (T, 15, 3) with T >= 1. "
                f"Got shape {joints.shape} instead."
            )
        if not np.all(np.isfinite(joints)):
            frame = int(np.argwhere(~np.isfinite(joints))[0][0])
            raise ValueError(
                f"The 'joints' argument of Motion must be finite. Got NaN or infinity at "
                f"frame {frame}."
            )
        extras = {}
        for key, value in dict(self.extras).items():
            if key not in EXTRA_POINT_NAMES:
                raise ValueError(
                    f"The 'extras' argument of Motion takes keys in {EXTRA_POINT_NAMES}. "
                    f"Got {key!r} instead."
                )
            arr = np.array(value, dtype=float)
            if arr.shape != (len(joints), 3) or not np.all(np.isfinite(arr)):
                raise ValueError(
                    f"Motion extra {key!r} must be a finite ({len(joints)}, 3) array. "
                    f"Got shape {arr.shape}."
                )
            arr.flags.writeable = False
            extras[key] = arr
        fps = check_scalar(self.fps, "fps", low=0.0, caller="Motion")
        joints.flags.writeable = False
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "extras", MappingProxyType(extras))
        object.__setattr__(self, "fps", fps)
        object.__setattr__(self, "meta", MappingProxyType(dict(self.meta)))

    def __len__(self) -> int:
        return int(self.joints.shape[0])

    @property
    def duration(self) -> float:
        """Seconds from the first to the last frame, ``(T - 1) / fps``."""
        return (len(self) - 1) / self.fps

    @cached_property
    def angles(self) -> np.ndarray:
        """``(T, 8)`` the eight angles of Table 1 in degrees (:func:`joint_angles`)."""
        angles = joint_angles(self.joints)
        angles.flags.writeable = False
        return angles

    def resample(self, fps: float) -> Motion:
        """The motion sampled at ``fps`` by linear interpolation of positions.

        Frames at ``t = k / fps`` for ``k = 0 .. floor(duration * fps)``: the first frame
        is kept exactly (a calibration T-pose stays frame 0); the last sample lies at or
        before the last frame. Linear interpolation of joint positions shortens a bone
        by at most ``1 - cos(w / 2)`` for a bone turning ``w`` between two source frames:
        at 60 or 120 fps source rates that is under 0.1 % for limbs moving below
        300 degrees per second.

        Parameters
        ----------
        fps : float
            The new frame rate, > 0.

        Returns
        -------
        Motion
        """
        fps = check_scalar(fps, "fps", low=0.0, caller="Motion.resample")
        if fps == self.fps:
            return self
        n = int(np.floor(self.duration * fps + 1e-6)) + 1
        src = np.arange(n) * (self.fps / fps)
        i0 = np.minimum(np.floor(src + 1e-9).astype(int), len(self) - 1)
        i1 = np.minimum(i0 + 1, len(self) - 1)
        frac = np.clip(src - i0, 0.0, 1.0)

        def interp(a: np.ndarray) -> np.ndarray:
            f = frac.reshape((-1,) + (1,) * (a.ndim - 1))
            return a[i0] * (1.0 - f) + a[i1] * f

        return Motion(
            interp(self.joints),
            {k: interp(v) for k, v in self.extras.items()},
            fps,
            self.name,
            {**self.meta, "resampled_from_fps": self.fps},
        )


_UP_NAMES = {"x": 0, "y": 1, "z": 2}


def _parse_up(up: str | None) -> np.ndarray | None:
    if up is None:
        return None
    text = str(up).strip().lower()
    sign = -1.0 if text.startswith("-") else 1.0
    axis = _UP_NAMES.get(text.lstrip("+-"))
    if axis is None:
        raise ValueError(
            f"The 'up' parameter of bvh_motion must be one of x, y, z, -x, -y, -z or None. "
            f"Got {up!r} instead."
        )
    v = np.zeros(3)
    v[axis] = sign
    return v


def _rotation_to_y(up: np.ndarray) -> np.ndarray:
    """A proper rotation taking the unit axis ``up`` onto +Y."""
    y = np.array([0.0, 1.0, 0.0])
    c = float(up @ y)
    if c > 1 - 1e-9:
        return np.eye(3)
    if c < -1 + 1e-9:
        return np.diag([1.0, -1.0, -1.0])  # half turn about X
    axis = np.cross(up, y)
    axis /= np.linalg.norm(axis)
    angle = np.arccos(np.clip(c, -1.0, 1.0))
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * (k @ k)


def _yaw(angle: float) -> np.ndarray:
    """Rotation by ``angle`` radians about +Y."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def _right_to_left(j: np.ndarray) -> np.ndarray:
    """The person's right-to-left direction from hips and shoulders, ``(..., 3)``."""
    return (j[..., _J["left_hip"], :] - j[..., _J["right_hip"], :]) + (
        j[..., _J["left_shoulder"], :] - j[..., _J["right_shoulder"], :]
    )


def to_world(
    joints: np.ndarray,
    extras: Mapping[str, np.ndarray],
    *,
    scale: float,
    up: np.ndarray,
    ankle_height: float,
) -> tuple[np.ndarray, dict[str, np.ndarray], bool]:
    """Move file-frame joints into the world frame.

    Scales to metres, rotates ``up`` onto +Y, turns about +Y so that the person faces
    +Z at frame 0 (forward = right-to-left x up, from hips and shoulders), puts the
    floor at y = 0 and the pelvis centre at x = z = 0. The floor is frame 0's lowest foot
    point (the lower ankle less ``ankle_height``, or a toe where lower), or the 5th
    percentile over frames of that point where lower (a clip that starts hanging from a
    bar or in a jump).
    Where the toes point backward (a left-handed file), the forward axis is mirrored.

    Returns
    -------
    joints : (T, 15, 3) float
    extras : dict
    mirrored : bool
    """
    a = _rotation_to_y(up) * scale
    j = joints @ a.T
    ex = {k: v @ a.T for k, v in extras.items()}
    r2l = _right_to_left(j[0])
    r2l[1] = 0.0
    forward = np.cross(r2l, [0.0, 1.0, 0.0])
    if np.linalg.norm(forward) < 1e-9:
        raise ValueError("cannot tell which way the person faces at frame 0 (no hip width).")
    turn = _yaw(-np.arctan2(forward[0], forward[2]))
    j = j @ turn.T
    ex = {k: v @ turn.T for k, v in ex.items()}
    mirrored = False
    if "left_toe" in ex and "right_toe" in ex:
        # Per frame: do the toes point along that frame's forward (right-to-left x up)?
        ahead = np.cross(_right_to_left(j), [0.0, 1.0, 0.0])
        toes = (ex["left_toe"] - j[:, _J["left_foot"]]) + (ex["right_toe"] - j[:, _J["right_foot"]])
        if np.median(np.sum(toes * ahead, axis=-1)) < 0:
            mirrored = True
            flip = np.diag([1.0, 1.0, -1.0])
            j = j @ flip
            ex = {k: v @ flip for k, v in ex.items()}
    # Per frame, the lowest foot point: an ankle less the ankle height, or a toe.
    lowest = np.minimum(j[:, _J["left_foot"], 1], j[:, _J["right_foot"], 1]) - ankle_height
    for k in ("left_toe", "right_toe"):
        if k in ex:
            lowest = np.minimum(lowest, ex[k][:, 1])
    # Frame 0's, unless the clip goes lower in more than 5 % of its frames (a clip that
    # starts hanging from a bar, or in a jump, stands on the ground later).
    floor = min(lowest[0], float(np.percentile(lowest, 5.0)))
    pelvis = 0.5 * (j[0, _J["left_hip"]] + j[0, _J["right_hip"]])
    shift = np.array([pelvis[0], floor, pelvis[2]])
    return j - shift, {k: v - shift for k, v in ex.items()}, mirrored


def bvh_motion(
    path: str | os.PathLike,
    *,
    rig: str | RigMap | Mapping[str, str] | None = None,
    scale: float | None = None,
    up: str | None = None,
) -> Motion:
    """A BVH clip as a :class:`Motion` on the 15-joint skeleton, in the world frame.

    Parameters
    ----------
    path : str or path-like
        The ``.bvh`` file.
    rig : str, RigMap, mapping or None
        The rig's name map (see :mod:`posedrift.synthetic._rigs`: ``"cmu-original"``,
        ``"cgspeed"``, ``"cc-base"``, ``"game"``, ``"unreal"``), a custom
        ``{joint name: node name}`` mapping, or None to detect it from the names.
    scale : float, optional
        Metres per file unit; detected from the skeleton's height when None (m, cm, mm,
        inches or the CMU scale 0.0254 / 0.45, whichever gives a stature closest to
        1.75 m).
    up : str, optional
        The file's up axis (``"y"``, ``"z"``, ``"-z"``...); detected when None as the
        axis along which head minus feet is largest (median over frames).

    Returns
    -------
    Motion
        At the file's frame rate; ``meta`` records the rig, units, up axis, stature,
        whether the file was mirrored (left-handed: toes pointing backward) and
        ``dropped_leading_frames``: leading frames detached from the motion (a joint
        moving faster than :data:`MAX_JOINT_SPEED` to the next frame, as a rest pose
        spliced at the origin) are dropped, so frame 0 is the clip's first real frame.

    Raises
    ------
    ValueError
        If the file is malformed (file and line named), or the rig cannot be mapped
        (the missing joints and the file's joint names listed), or no human height
        fits any unit.
    """
    path = Path(path)
    bvh = load_bvh(path)
    resolved = resolve_rig(bvh.names, rig=rig, source=str(path))
    nodes = resolved.nodes
    positions = bvh.positions([bvh.names[i] for i in nodes])
    joints, extras = map_positions(resolved, positions)
    stature = stature_estimate(joints, extras)
    if scale is None:
        units, scale = detect_units(stature, source=str(path))
    else:
        scale = check_scalar(scale, "scale", low=0.0, caller="bvh_motion")
        units = f"{scale:g} m per unit"
    up_axis = _parse_up(up)
    if up_axis is None:
        up_axis = detect_up_axis(joints)
    height = stature * scale
    # A leading rest pose spliced in far from the motion (007_03..12 hold a T-pose at
    # the origin, 2.4-3 m from frame 1) is no calibration frame: drop it.
    dropped = 0
    limit = MAX_JOINT_SPEED / bvh.fps / scale
    while len(joints) - dropped > 2:
        step = np.linalg.norm(joints[dropped + 1] - joints[dropped], axis=-1).max()
        if step <= limit:
            break
        dropped += 1
    if dropped:
        joints = joints[dropped:]
        extras = {k: v[dropped:] for k, v in extras.items()}
    joints, extras, mirrored = to_world(
        joints, extras, scale=scale, up=up_axis, ankle_height=0.039 * height
    )
    axis_name = ("-" if up_axis.sum() < 0 else "") + "xyz"[int(np.argmax(np.abs(up_axis)))]
    meta = {
        "source": str(path),
        "rig": resolved.rig.name,
        "units": units,
        "scale": scale,
        "up": axis_name,
        "stature_m": height,
        "mirrored": mirrored,
        "dropped_leading_frames": dropped,
    }
    return Motion(joints, extras, bvh.fps, path.stem, meta)


# --------------------------------------------------------------------------- calibration


def is_t_pose(joints: np.ndarray, *, tolerance: float = 15.0) -> bool:
    """Whether one frame ``(15, 3)`` (world frame, +Y up) is a T-pose.

    Shoulders within ``tolerance`` degrees of 90, elbows and knees within
    ``tolerance`` of straight (180), hips within ``tolerance`` of 0 and the trunk
    (pelvis centre to neck) within ``tolerance`` of vertical.

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> is_t_pose(t_pose_joints(1.6))
    True
    """
    j = np.asarray(joints, dtype=float)
    names = ("le", "re", "ls", "rs", "lk", "rk", "lh", "rh")
    a = dict(zip(names, joint_angles(j), strict=True))
    trunk = j[_J["neck"]] - 0.5 * (j[_J["left_hip"]] + j[_J["right_hip"]])
    tilt = np.degrees(np.arccos(np.clip(trunk[1] / np.linalg.norm(trunk), -1.0, 1.0)))
    return bool(
        all(abs(a[k] - 90.0) <= tolerance for k in ("ls", "rs"))
        and all(a[k] >= 180.0 - tolerance for k in ("le", "re", "lk", "rk"))
        and all(a[k] <= tolerance for k in ("lh", "rh"))
        and tilt <= tolerance
    )


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return v / np.where(n > 0, n, 1.0)


def _slerp_dirs(a: np.ndarray, b: np.ndarray, w: np.ndarray, hint: np.ndarray) -> np.ndarray:
    """Unit directions from ``a`` to ``b`` (both ``(3,)`` unit) at weights ``w``, ``(n, 3)``.

    Antiparallel ends turn about ``hint`` (made perpendicular to ``a``).
    """
    angle = float(np.arccos(np.clip(a @ b, -1.0, 1.0)))
    if angle < 1e-9:
        return np.repeat(a[None], len(w), axis=0)
    if np.pi - angle < 1e-6:
        perp = _unit(hint - (hint @ a) * a)
        if np.linalg.norm(perp) < 0.5:
            perp = _unit(np.cross(a, [1.0, 0.0, 0.0]) + np.cross(a, [0.0, 0.0, 1.0]))
        b_axis = perp
        return np.cos(w * angle)[:, None] * a + np.sin(w * angle)[:, None] * b_axis
    s = np.sin(angle)
    return (np.sin((1 - w) * angle)[:, None] * a + np.sin(w * angle)[:, None] * b) / s


# Bones rebuilt by direction slerp, parent first; the trunk (neck, shoulders, torso,
# hips) moves as one rigid body about the pelvis centre.
_TRUNK = ("neck", "right_shoulder", "left_shoulder", "torso", "right_hip", "left_hip")
_LIMB_BONES = (
    ("neck", "head"),
    ("head", "head_top"),
    ("left_shoulder", "left_elbow"),
    ("left_elbow", "left_hand"),
    ("left_hand", "left_hand_tip"),
    ("right_shoulder", "right_elbow"),
    ("right_elbow", "right_hand"),
    ("right_hand", "right_hand_tip"),
    ("left_hip", "left_knee"),
    ("left_knee", "left_foot"),
    ("left_foot", "left_toe"),
    ("right_hip", "right_knee"),
    ("right_knee", "right_foot"),
    ("right_foot", "right_toe"),
)


def _trunk_frame(j: np.ndarray) -> np.ndarray:
    """Trunk-to-world rotation (columns: left, up, forward) of one frame ``(15, 3)``."""
    pelvis = 0.5 * (j[_J["left_hip"]] + j[_J["right_hip"]])
    y = _unit(j[_J["neck"]] - pelvis)
    x = _right_to_left(j)
    x = _unit(x - (x @ y) * y)
    return np.stack([x, y, np.cross(x, y)], axis=1)


def calibration_t_pose(
    joints: np.ndarray, extras: Mapping[str, np.ndarray] | None = None
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A T-pose of the skeleton of one frame, at its place and facing.

    Bone lengths come from the frame; the trunk (neck, shoulders, torso, hips) keeps
    its shape and is stood upright, facing the frame's horizontal forward direction;
    arms horizontal sideways, legs straight down, the head above the neck, hand tips
    in line with the arms, toes forward and down to the floor. The pelvis centre keeps
    its x and z; the lower ankle stands at the frame's lower ankle height (at least 0).

    Parameters
    ----------
    joints : (15, 3) float
        One frame, world frame (+Y up, floor y = 0).
    extras : mapping of str to (3,) float, optional

    Returns
    -------
    joints : (15, 3) float
    extras : dict of str to (3,) float

    Examples
    --------
    >>> from posedrift.skeleton import joint_angles, t_pose_joints
    >>> j, _ = calibration_t_pose(t_pose_joints(1.75))
    >>> bool(np.allclose(j, t_pose_joints(1.75)))
    True
    """
    j0 = np.asarray(joints, dtype=float)
    ex0 = {k: np.asarray(v, dtype=float) for k, v in (extras or {}).items()}
    up = np.array([0.0, 1.0, 0.0])
    r0 = _trunk_frame(j0)
    forward = r0[:, 2].copy()
    forward[1] = 0.0
    if np.linalg.norm(forward) < 1e-6:  # lying face down/up: use the trunk's up instead
        forward = -np.sign(r0[1, 2] or 1.0) * r0[:, 1]
        forward[1] = 0.0
    forward = _unit(forward)
    rt = np.stack([np.cross(up, forward), up, forward], axis=1)
    pelvis0 = 0.5 * (j0[_J["left_hip"]] + j0[_J["right_hip"]])
    local = {n: r0.T @ (j0[_J[n]] - pelvis0) for n in _TRUNK}
    length = {}
    points = {n: j0[_J[n]] for n in JOINT_NAMES} | ex0
    for parent, child in _LIMB_BONES:
        if parent in points and child in points:
            length[child] = float(np.linalg.norm(points[child] - points[parent]))
    ankle0 = max(min(j0[_J["left_foot"], 1], j0[_J["right_foot"], 1]), 0.0)
    lowest = min(
        (rt @ local[f"{s}_hip"])[1] - length[f"{s}_knee"] - length[f"{s}_foot"]
        for s in ("left", "right")
    )
    pelvis = np.array([pelvis0[0], ankle0 - lowest, pelvis0[2]])
    out = {n: pelvis + rt @ local[n] for n in _TRUNK}
    left = rt[:, 0]
    direction = {
        "head": up,
        "head_top": up,
        "left_elbow": left,
        "left_hand": left,
        "left_hand_tip": left,
        "right_elbow": -left,
        "right_hand": -left,
        "right_hand_tip": -left,
        "left_knee": -up,
        "left_foot": -up,
        "right_knee": -up,
        "right_foot": -up,
    }
    for parent, child in _LIMB_BONES:
        if child not in length:
            continue
        if child.endswith("_toe"):
            drop = min(ankle0 / length[child], 0.9) if length[child] > 0 else 0.0
            d = np.sqrt(1 - drop**2) * forward - drop * up
        else:
            d = direction[child]
        out[child] = out[parent] + length[child] * d
    out_joints = np.array([out[n] for n in JOINT_NAMES])
    return out_joints, {k: out[k] for k in ex0}


def with_calibration_pose(motion: Motion, *, blend_seconds: float = 1.0) -> Motion:
    """The motion with a calibration T-pose as frame 0.

    Where frame 0 is already a T-pose (:func:`is_t_pose`), the motion is returned
    unchanged. Else a T-pose of the same skeleton (:func:`calibration_t_pose`) is
    prepended and blended into the clip's first frame over ``blend_seconds``: the
    trunk turns by rotation slerp, every limb bone by direction slerp with its length
    fixed (bone lengths never shrink mid-blend), with a cosine ease. The clip follows
    unchanged, so the result has ``round(blend_seconds * fps)`` more frames.

    Parameters
    ----------
    motion : Motion
    blend_seconds : float
        Length of the blend, > 0.

    Returns
    -------
    Motion
        ``meta["calibration_frames"]`` gives the number of frames prepended.

    Examples
    --------
    >>> from posedrift.synthetic import procedural_motion
    >>> m = procedural_motion(seconds=2.0)
    >>> with_calibration_pose(m) is m
    True
    """
    from scipy.spatial.transform import Rotation, Slerp

    blend_seconds = check_scalar(
        blend_seconds, "blend_seconds", low=0.0, caller="with_calibration_pose"
    )
    if not isinstance(motion, Motion):
        raise ValueError(
            f"The 'motion' argument of with_calibration_pose must be a Motion. "
            f"Got {type(motion).__name__} instead."
        )
    j0 = motion.joints[0]
    if is_t_pose(j0):
        return motion
    n = max(round(blend_seconds * motion.fps), 1)
    ex0 = {k: v[0] for k, v in motion.extras.items()}
    jt, ext = calibration_t_pose(j0, ex0)
    w = 0.5 - 0.5 * np.cos(np.pi * np.arange(n) / n)  # 0 .. just below 1
    r_t, r_0 = _trunk_frame(jt), _trunk_frame(j0)
    rots = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([r_t, r_0])))(w).as_matrix()
    pel_t = 0.5 * (jt[_J["left_hip"]] + jt[_J["right_hip"]])
    pel_0 = 0.5 * (j0[_J["left_hip"]] + j0[_J["right_hip"]])
    pelvis = pel_t + w[:, None] * (pel_0 - pel_t)
    out: dict[str, np.ndarray] = {}
    for name in _TRUNK:
        local = r_0.T @ (j0[_J[name]] - pel_0)
        out[name] = pelvis + rots @ local
    start = {n: jt[_J[n]] for n in JOINT_NAMES} | ext
    end = {n: j0[_J[n]] for n in JOINT_NAMES} | ex0
    for parent, child in _LIMB_BONES:
        if child not in end:
            continue
        a, b = start[child] - start[parent], end[child] - end[parent]
        length = float(np.linalg.norm(b))
        d = _slerp_dirs(_unit(a), _unit(b), w, hint=r_0[:, 2])
        out[child] = out[parent] + length * d
    blend_joints = np.stack([out[n] for n in JOINT_NAMES], axis=1)
    joints = np.concatenate([blend_joints, motion.joints])
    extras = {k: np.concatenate([out[k], v]) for k, v in motion.extras.items()}
    meta = {**motion.meta, "calibration_frames": n}
    return Motion(joints, extras, motion.fps, motion.name, meta)
