"""The eight joint angles of Table 1, from 3-D joint positions alone."""

from __future__ import annotations

import math

import numpy as np

from posedrift.skeleton._definitions import ANGLE_NAMES, JOINT_INDEX, JOINT_NAMES

# (vertex joint, first arm end, second arm end) for the elbow and knee angles.
_HINGES = {
    "left_elbow": ("left_elbow", "left_shoulder", "left_hand"),
    "right_elbow": ("right_elbow", "right_shoulder", "right_hand"),
    "left_knee": ("left_knee", "left_hip", "left_foot"),
    "right_knee": ("right_knee", "right_hip", "right_foot"),
}
# (proximal joint, distal joint): the limb measured against the trunk's downward axis.
_TRUNK_RELATIVE = {
    "left_shoulder": ("left_shoulder", "left_elbow"),
    "right_shoulder": ("right_shoulder", "right_elbow"),
    "left_hip": ("left_hip", "left_knee"),
    "right_hip": ("right_hip", "right_knee"),
}
_TRUNK = ("neck", "left_hip", "right_hip")  # the trunk's downward axis

ANGLE_JOINTS: dict[str, tuple[str, ...]] = {
    name: _HINGES[name] if name in _HINGES else tuple(dict.fromkeys(_TRUNK_RELATIVE[name] + _TRUNK))
    for name in ANGLE_NAMES
}
"""The joints each of the eight angles is computed from (:func:`joint_angles`)."""


def _angle_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle in degrees between vectors along the last axis; NaN where either is zero."""
    cross = np.linalg.norm(np.cross(a, b), axis=-1)
    dot = np.sum(a * b, axis=-1)
    with np.errstate(invalid="ignore"):
        angle = np.degrees(np.arctan2(cross, dot))
    degenerate = (np.linalg.norm(a, axis=-1) == 0) | (np.linalg.norm(b, axis=-1) == 0)
    return np.where(degenerate, np.nan, angle)


def pelvis_centre(joints: np.ndarray) -> np.ndarray:
    """The mean of the two hips, ``(..., 3)``."""
    joints = np.asarray(joints, dtype=float)
    return 0.5 * (
        joints[..., JOINT_INDEX["right_hip"], :] + joints[..., JOINT_INDEX["left_hip"], :]
    )


def joint_angles(joints: np.ndarray) -> np.ndarray:
    """The eight angles of Table 1, in degrees.

    The same function computes ground truth and estimates (``METHOD.md`` section 2):
    elbow and knee are the angle at the joint between its two segments (180 when
    straight); shoulder and hip are the angle between the limb's first segment and
    the trunk's downward axis ``pelvis_centre - neck`` (about 0 when hanging, 90 in
    a T-pose).

    Parameters
    ----------
    joints : (..., 15, 3) float
        Joint positions in any consistent unit, in :data:`JOINT_NAMES` order.

    Returns
    -------
    angles : (..., 8) float
        In :data:`ANGLE_NAMES` order; NaN where a needed joint is NaN or two
        joints coincide.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.skeleton import joint_angles, t_pose_joints
    >>> np.round(joint_angles(t_pose_joints(1.75)), 1)
    array([180., 180.,  90.,  90., 180., 180.,   0.,   0.])
    """
    joints = np.asarray(joints, dtype=float)
    if joints.shape[-2:] != (len(JOINT_NAMES), 3):
        raise ValueError(
            f"The 'joints' argument of joint_angles must have shape (..., 15, 3). "
            f"Got shape {joints.shape} instead."
        )
    j = {name: joints[..., i, :] for name, i in JOINT_INDEX.items()}
    down = pelvis_centre(joints) - j["neck"]
    out = []
    for name in ANGLE_NAMES:
        if name in _HINGES:
            vertex, a, b = _HINGES[name]
            out.append(_angle_between(j[a] - j[vertex], j[b] - j[vertex]))
        else:
            proximal, distal = _TRUNK_RELATIVE[name]
            out.append(_angle_between(j[distal] - j[proximal], down))
    return np.stack(out, axis=-1)


def angles_dict(angles: np.ndarray) -> dict[str, float | None]:
    """One frame's eight angles as ``{name: degrees}``; NaN becomes None (for JSON)."""
    return {
        name: (None if not np.isfinite(value) else float(value))
        for name, value in zip(ANGLE_NAMES, np.asarray(angles, dtype=float), strict=True)
    }


def facing_yaw(
    joints: np.ndarray, *, up: np.ndarray | None = None, signed: bool = False
) -> np.ndarray:
    """How far the person is turned away from the camera, in degrees.

    The person's facing direction is horizontal and at right angles to the line
    from the right to the left hip and shoulder (averaged); ``facing_yaw`` is its
    angle to the direction from the pelvis to the camera (the origin of the camera
    frame): 0 faces the camera, 90 a side view, 180 the back to the camera.
    ``signed`` tells which way: positive where the person's left side is nearer the
    camera than the right (the line from right to left points towards the camera).

    Parameters
    ----------
    joints : (..., 15, 3) float
        Camera frame (OpenCV: +Y down), metres.
    up : (3,) float, optional
        The world's up direction in the camera frame; default ``(0, -1, 0)``.
    signed : bool
        Degrees in [-180, 180] instead: negative where the right side is nearer.

    Returns
    -------
    (...) float
        Degrees in [0, 180]; NaN where the hips and shoulders are unknown.

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> world = t_pose_joints(1.75)  # +Y up, facing +Z
    >>> camera = world * [1.0, -1.0, -1.0] + [0.0, 0.0, 3.0]  # seen from +Z, 3 m away
    >>> round(float(facing_yaw(camera)), 6)
    0.0
    >>> turned = camera * [-1.0, 1.0, -1.0] + [0.0, 0.0, 6.0]  # turned about the vertical
    >>> round(float(facing_yaw(turned)), 6)
    180.0
    >>> c, s = np.cos(np.radians(80)), np.sin(np.radians(80))
    >>> left = (camera - [0, 0, 3]) @ [[c, 0, -s], [0, 1, 0], [s, 0, c]] + [0, 0, 3]
    >>> hips = JOINT_INDEX["left_hip"], JOINT_INDEX["right_hip"]
    >>> bool(left[hips[0], 2] < left[hips[1], 2])  # turned: the left hip nearer
    True
    >>> round(float(facing_yaw(left, signed=True)), 6)
    80.0
    """
    joints = np.asarray(joints, dtype=float)
    if up is None and joints.shape == (len(JOINT_NAMES), 3):
        return np.float64(_facing_yaw_one(joints, signed))
    up = np.array([0.0, -1.0, 0.0]) if up is None else np.asarray(up, dtype=float)
    j = JOINT_INDEX
    across = (
        joints[..., j["left_hip"], :]
        - joints[..., j["right_hip"], :]
        + joints[..., j["left_shoulder"], :]
        - joints[..., j["right_shoulder"], :]
    )
    facing = np.cross(across, up)  # left x up = forward for a right-handed body frame
    facing = facing - (facing @ up)[..., None] * up
    to_camera = -pelvis_centre(joints)
    to_camera = to_camera - (to_camera @ up)[..., None] * up
    yaw = _angle_between(facing, to_camera)
    if signed:  # the across line's component towards the camera tells which side
        yaw = np.where(np.sum(across * to_camera, axis=-1) < 0, -yaw, yaw)
    return yaw


def _facing_yaw_one(joints: np.ndarray, signed: bool = False) -> float:
    """:func:`facing_yaw` of one skeleton with the default up, in Python floats.

    The tracker asks twice a frame, and NumPy's calls on small arrays cost 25 times
    the arithmetic (59 against 2.3 microseconds). With up ``(0, -1, 0)`` every product
    with up is exact, so the facing and camera directions are ``(a_z, 0, -a_x)`` and
    ``(c_x, 0, c_z)``, and this is the array path's arithmetic to the last bit (with
    NumPy's own arctan2: libm's can differ in the last bit; see
    ``tests/test_skeleton_definitions.py``).
    """
    j = JOINT_INDEX
    lhx, _, lhz = joints[j["left_hip"]].tolist()
    rhx, _, rhz = joints[j["right_hip"]].tolist()
    lsx, _, lsz = joints[j["left_shoulder"]].tolist()
    rsx, _, rsz = joints[j["right_shoulder"]].tolist()
    ax, az = ((lhx - rhx) + lsx) - rsx, ((lhz - rhz) + lsz) - rsz
    cx, cz = -(0.5 * (rhx + lhx)), -(0.5 * (rhz + lhz))
    if (ax == 0.0 and az == 0.0) or (cx == 0.0 and cz == 0.0):
        return math.nan
    cross = abs(-ax * cx - az * cz)
    dot = az * cx + -ax * cz
    yaw = float(np.degrees(np.arctan2(cross, dot)))
    return -yaw if signed and ax * cx + az * cz < 0 else yaw
