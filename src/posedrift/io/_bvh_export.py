"""BVH export of recovered motion on the 15-joint skeleton.

The hierarchy is :data:`posedrift.skeleton.JOINT_PARENTS` rooted at ``torso``, the
joint names are :data:`posedrift.skeleton.JOINT_NAMES`, and the rest pose is a
T-pose with per-sequence median bone lengths.

Frame of the file: Y up, centimetres, the person facing +Z when facing the
camera: ``p_bvh = 100 * (x, -y, -z)`` for a camera-frame point ``(x, y, z)`` in
metres (a rotation of 180 degrees about X).

Rotations: every joint carries ``Zrotation Xrotation Yrotation`` (local
``R = Rz Rx Ry``). A joint with one child turns to point its bone at the child,
so forward kinematics reproduce that child exactly when the bone length is
constant over the sequence (the tracker keeps its calibrated lengths).
``torso`` and ``neck`` have three children each, whose layout (spine bend,
shrug, head nod) one rotation cannot follow; their children therefore also
carry ``Xposition Yposition Zposition`` channels that hold the child's full
local offset (the channel values replace the OFFSET, as Blender and bvhio read
them), so they are reproduced exactly whatever the lengths. So does any joint whose
bone length varies over the sequence by more than ``length_tolerance`` (joints
moved to another convention, e.g. the Kinect SDK's, whose bones stretch).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from posedrift.skeleton import JOINT_NAMES, JOINT_PARENTS, SEGMENT_RATIOS, t_pose_joints

_CAMERA_TO_BVH = np.diag([1.0, -1.0, -1.0])
_CM = 100.0
_ROOT = JOINT_PARENTS.index(-1)
_CHILDREN: tuple[tuple[int, ...], ...] = tuple(
    tuple(c for c, p in enumerate(JOINT_PARENTS) if p == j) for j in range(len(JOINT_NAMES))
)
_BRANCH_CHILD = tuple(p >= 0 and len(_CHILDREN[p]) > 1 for p in JOINT_PARENTS)
"""Joints whose parent has several children: they get position channels."""


def _order() -> list[int]:
    """Joints parents-first (depth-first, children in index order)."""
    out, stack = [], [_ROOT]
    while stack:
        j = stack.pop()
        out.append(j)
        stack.extend(reversed(_CHILDREN[j]))
    return out


_ORDER = _order()


def camera_to_bvh(points: np.ndarray) -> np.ndarray:
    """Camera-frame metres ``(..., 3)`` to the BVH file's frame (Y up, centimetres)."""
    return _CM * np.asarray(points, dtype=float) @ _CAMERA_TO_BVH.T


def bvh_to_camera(points: np.ndarray) -> np.ndarray:
    """Inverse of :func:`camera_to_bvh`."""
    return np.asarray(points, dtype=float) @ _CAMERA_TO_BVH / _CM


def _kabsch(rest: np.ndarray, current: np.ndarray) -> np.ndarray:
    """The rotation that best maps the rows of ``rest`` onto those of ``current``."""
    u, _, vt = np.linalg.svd(rest.T @ current)
    d = np.sign(np.linalg.det(vt.T @ u.T)) or 1.0
    return vt.T @ np.diag([1.0, 1.0, d]) @ u.T


def _align(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The smallest rotation taking direction ``a`` to direction ``b``."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        # opposite: half-turn about any axis perpendicular to a
        axis = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(axis) < 1e-6:
            axis = np.cross(a, [0.0, 1.0, 0.0])
        axis /= np.linalg.norm(axis)
        return 2.0 * np.outer(axis, axis) - np.eye(3)
    k = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]])
    return np.eye(3) + k + k @ k * ((1.0 - c) / s**2)


def fill_unknown_frames(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Hold the last known pose over frames with unknown joints.

    Parameters
    ----------
    joints : (T, 15, 3) float
        NaN where unknown; a frame counts as known only when all 15 joints are.

    Returns
    -------
    filled : (T, 15, 3) float
        Frames before the first known one take the first known pose.
    held : (T,) bool
        Which frames were filled.

    Raises
    ------
    ValueError
        If no frame has a complete pose.
    """
    joints = np.asarray(joints, dtype=float)
    known = np.isfinite(joints).all(axis=(1, 2))
    if not known.any():
        raise ValueError("No frame has a complete pose: there is no motion to export to BVH.")
    index = np.where(known, np.arange(len(joints)), -1)
    index = np.maximum.accumulate(index)
    index[index < 0] = int(np.argmax(known))
    return joints[index], ~known


def bone_offsets(joints: np.ndarray) -> np.ndarray:
    """Rest offsets ``(15, 3)`` in the BVH frame: T-pose directions, median lengths (cm)."""
    rest = t_pose_joints(1.75)
    offsets = np.zeros((len(JOINT_NAMES), 3))
    for j, p in enumerate(JOINT_PARENTS):
        if p < 0:
            continue
        length = np.median(np.linalg.norm(joints[:, j] - joints[:, p], axis=-1))
        direction = rest[j] - rest[p]
        offsets[j] = length * direction / np.linalg.norm(direction)
    return offsets


def _euler_zxy(matrix: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(matrix).as_euler("ZXY", degrees=True)


def positioned_joints(joints_bvh: np.ndarray, tolerance_cm: float) -> np.ndarray:
    """``(15,)`` bool: the joints written with position channels.

    The children of a branching joint, and every joint whose bone length (in the
    BVH frame, centimetres) strays from its median by more than ``tolerance_cm``.
    """
    out = np.array(_BRANCH_CHILD)
    for j, p in enumerate(JOINT_PARENTS):
        if p >= 0:
            length = np.linalg.norm(joints_bvh[:, j] - joints_bvh[:, p], axis=-1)
            out[j] |= bool(np.max(np.abs(length - np.median(length))) > tolerance_cm)
    return out


def motion_channels(
    joints_bvh: np.ndarray, offsets: np.ndarray, positioned: np.ndarray | None = None
) -> np.ndarray:
    """Per-frame channel values ``(T, C)`` in file order for joints in the BVH frame.

    ``positioned`` (default: the children of branching joints) marks the joints
    that carry position channels (:func:`positioned_joints`).
    """
    positioned = np.array(_BRANCH_CHILD) if positioned is None else positioned
    rows = []
    for frame in joints_bvh:
        rotation = {}
        values = []
        for j in _ORDER:
            p = JOINT_PARENTS[j]
            parent_rotation = np.eye(3) if p < 0 else rotation[p]
            children = _CHILDREN[j]
            if len(children) > 1:
                rest = offsets[list(children)]
                now = frame[list(children)] - frame[j]
                world = _kabsch(rest, now)
            elif len(children) == 1:
                c = children[0]
                world = _align(parent_rotation @ offsets[c], frame[c] - frame[j]) @ parent_rotation
            else:
                world = parent_rotation
            rotation[j] = world
            if p < 0:
                values.extend(frame[j])
            elif positioned[j]:
                values.extend(parent_rotation.T @ (frame[j] - frame[p]))
            values.extend(_euler_zxy(parent_rotation.T @ world))
        rows.append(values)
    return np.asarray(rows)


def _end_site(j: int, height_cm: float) -> np.ndarray:
    r = SEGMENT_RATIOS
    name = JOINT_NAMES[j]
    if name == "head":
        return np.array([0.0, 0.5 * r["head_height"] * height_cm, 0.0])
    if name.endswith("hand"):
        sign = 1.0 if name.startswith("left") else -1.0
        return np.array([sign * r["hand"] * height_cm, 0.0, 0.0])
    return np.array([0.0, -r["ankle_height"] * height_cm, r["foot_length"] * height_cm * 0.7])


def write_bvh(
    joints: np.ndarray,
    path: str | Path,
    *,
    fps: float = 30.0,
    length_tolerance: float = 0.005,
) -> tuple[Path, np.ndarray]:
    """Write a ``(T, 15, 3)`` camera-frame joint sequence as BVH.

    Parameters
    ----------
    joints : (T, 15, 3) float
        Metres, camera frame, NaN where unknown (such frames hold the last known pose).
    path : str or Path
        The ``.bvh`` file to write.
    fps : float
        Frames per second (``Frame Time`` is ``1 / fps``).
    length_tolerance : float
        Metres: a bone whose length strays further than this from its median gets
        position channels on its child joint, so that the file reproduces the joints
        exactly (the tracker's native limb lengths are constant and need none).

    Returns
    -------
    path : Path
    held : (T,) bool
        Frames written with a held pose.

    Raises
    ------
    ValueError
        If ``joints`` has the wrong shape or no frame has a complete pose.

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from posedrift.skeleton import t_pose_joints
    >>> joints = np.stack([t_pose_joints(1.7), t_pose_joints(1.7) + 0.01])
    >>> out = pathlib.Path(tempfile.mkdtemp()) / "pose.bvh"
    >>> path, held = write_bvh(joints, out)
    >>> path.read_text().splitlines()[:2], held.tolist()
    (['HIERARCHY', 'ROOT torso'], [False, False])
    """
    joints = np.asarray(joints, dtype=float)
    if joints.ndim != 3 or joints.shape[1:] != (len(JOINT_NAMES), 3):
        raise ValueError(
            f"The 'joints' argument of write_bvh must have shape (T, 15, 3). Got {joints.shape}."
        )
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"The 'fps' of write_bvh must be positive. Got {fps!r} instead.")
    filled, held = fill_unknown_frames(joints)
    in_bvh = camera_to_bvh(filled)
    offsets = bone_offsets(in_bvh)
    positioned = positioned_joints(in_bvh, _CM * length_tolerance)
    height_cm = float(
        np.median(
            in_bvh[:, JOINT_NAMES.index("head"), 1] - in_bvh[:, JOINT_NAMES.index("right_foot"), 1]
        )
    )
    height_cm = max(height_cm, 100.0)
    lines = ["HIERARCHY"]

    def emit(j: int, depth: int) -> None:
        pad = "  " * depth
        keyword = "ROOT" if JOINT_PARENTS[j] < 0 else "JOINT"
        lines.append(f"{pad}{keyword} {JOINT_NAMES[j]}")
        lines.append(f"{pad}{{")
        lines.append(f"{pad}  OFFSET " + " ".join(f"{v:.6f}" for v in offsets[j]))
        if JOINT_PARENTS[j] < 0 or positioned[j]:
            channels = "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"
        else:
            channels = "CHANNELS 3 Zrotation Xrotation Yrotation"
        lines.append(f"{pad}  {channels}")
        if not _CHILDREN[j]:
            lines.append(f"{pad}  End Site")
            lines.append(f"{pad}  {{")
            end = _end_site(j, height_cm)
            lines.append(f"{pad}    OFFSET " + " ".join(f"{v:.6f}" for v in end))
            lines.append(f"{pad}  }}")
        for c in _CHILDREN[j]:
            emit(c, depth + 1)
        lines.append(f"{pad}}}")

    emit(_ROOT, 0)
    channels = motion_channels(in_bvh, offsets, positioned)
    lines.append("MOTION")
    lines.append(f"Frames: {len(channels)}")
    lines.append(f"Frame Time: {1.0 / fps:.8f}")
    lines.extend(" ".join(f"{v:.6f}" for v in row) for row in channels)
    path = Path(path)
    path.write_text("\n".join(lines) + "\n")
    return path, held


def bvh_joint_order() -> Sequence[str]:
    """Joint names in the order they appear in the file."""
    return [JOINT_NAMES[j] for j in _ORDER]
