"""Joints the camera cannot see: the trunk continued out of the image, limbs held on it.

Where a climber's head and arms rise above the image, no point carries their labels and
:func:`~posedrift.skeleton.fit_skeleton` fills them in from the prediction: the last
joints carried by the motion of the points in view, which are then the hips and legs, not
the trunk the arms hang from; and the neck, which has no boundary where the torso is cut,
stays near the image's edge, the trunk shortened. Here the trunk goes on out of the
image along the torso's visible axis for its calibrated length (:func:`continue_trunk`),
and each unseen limb keeps the pose it had relative to the trunk in the last frame
(:func:`hold_limbs`). On the development clips this took the climb (001_08) from 15.31
to 13.61 degrees over five samples (docs/results-log.md).
"""

from __future__ import annotations

import math

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, JOINT_PARENTS, PART_INDEX
from posedrift.skeleton._fit import _trunk_axes, _unit

_J = JOINT_INDEX
_NECK, _TORSO, _RIGHT_HIP, _LEFT_HIP = _J["neck"], _J["torso"], _J["right_hip"], _J["left_hip"]
_UPPER_TORSO, _LOWER_TORSO = PART_INDEX["upper_torso"], PART_INDEX["lower_torso"]

MIN_UPPER_TORSO_POINTS = 15
"""Fewest upper-torso points for the trunk to be continued (of about 400): with less in
view (a body at 2.0 m seen from the hips down) the torso's axis is a guess. In one sample
continuing it regardless moved the whole skeleton off; over five, 0-20 points were alike
(docs/results-log.md)."""

MAX_TRUNK_TURN = 35.0
"""Degrees the torso's visible axis may turn from the last frame's trunk; beyond (or for
torso points too round to have an axis, ``MIN_TORSO_ELONGATION``) the last trunk's
direction is kept."""

MIN_TORSO_ELONGATION = 2.0
"""Smallest ratio of the torso points' two largest variances for their axis to count."""

HELD_JOINTS: tuple[str, ...] = ("head", "right_elbow", "left_elbow", "right_hand", "left_hand")
"""The joints :func:`hold_limbs` holds, each after its parent. The legs are not held: at
2.0 m holding them changed one clip by -0.3 and another by +0.5 degrees."""

_MOVED_WITH_NECK = tuple(
    _J[n]
    for n in ("head", "right_shoulder", "left_shoulder", "right_elbow", "left_elbow")
    + ("right_hand", "left_hand")
)


def _pelvis(joints: np.ndarray) -> np.ndarray:
    return 0.5 * (joints[_RIGHT_HIP] + joints[_LEFT_HIP])


def continue_trunk(
    joints: np.ndarray,
    measured: np.ndarray,
    points: np.ndarray,
    labels: np.ndarray,
    *,
    previous: np.ndarray,
    exits: np.ndarray,
    bone_lengths: np.ndarray,
    min_points: int = MIN_UPPER_TORSO_POINTS,
) -> np.ndarray:
    """The neck set where the trunk goes on out of the image, where it was not measured.

    Applies where the neck has no boundary of its own (not ``measured``) and the upper
    torso is cut by the image's edge (its row of ``exits`` finite): the neck is put the
    trunk's length (twice the neck's bone) from the pelvis along the torso points'
    principal axis, turned towards where the upper torso leaves the image, or along the
    last frame's trunk where that axis is not trustworthy (``MAX_TRUNK_TURN``,
    ``MIN_TORSO_ELONGATION``). The unmeasured head, shoulder and arm joints move with the
    neck; the torso joint stays midway between the neck and the pelvis.

    Parameters
    ----------
    joints : (15, 3) float
        This frame's fitted skeleton, all finite.
    measured : (15,) bool
        Which joints came from this frame's labels.
    points : (N, 3) float
    labels : (N,) int
        This frame's labelled points.
    previous : (15, 3) float
        The last frame's skeleton, all finite.
    exits : (15, 3) float
        Where each part leaves the image (NaN for parts inside it;
        :func:`~posedrift.skeleton.image_exits`).
    bone_lengths : (15,) float
        The calibrated bones (``fit_skeleton``'s).
    min_points : int
        Fewest upper-torso points for the axis to be measured at all.

    Returns
    -------
    (15, 3) float
        A new array; ``joints`` itself where nothing applies.
    """
    upper_torso_exit = exits[_UPPER_TORSO]
    if measured[_NECK] or not np.isfinite(upper_torso_exit).all():
        return joints
    upper = labels == _UPPER_TORSO
    if np.count_nonzero(upper) < min_points:
        return joints
    torso = points[upper | (labels == _LOWER_TORSO)]
    pelvis = _pelvis(joints)
    last_up = _unit(previous[_NECK] - _pelvis(previous))  # NaN for a degenerate trunk
    centred = torso - torso.mean(axis=0)
    variances, axes = np.linalg.eigh(centred.T @ centred)
    axis = axes[:, 2]
    if axis @ (upper_torso_exit - pelvis) < 0:
        axis = -axis
    straight = axis @ last_up >= math.cos(math.radians(MAX_TRUNK_TURN))
    if not (straight and variances[2] >= MIN_TORSO_ELONGATION * variances[1]):
        axis = last_up
    if not np.isfinite(axis).all():
        return joints
    out = joints.copy()
    # The torso joint is midway between the neck and the pelvis: the trunk is twice its bone.
    shift = pelvis + 2.0 * bone_lengths[_NECK] * axis - joints[_NECK]
    out[_NECK] += shift
    moved = [j for j in _MOVED_WITH_NECK if not measured[j]]
    out[moved] += shift
    out[_TORSO] = 0.5 * (out[_NECK] + pelvis)
    return out


def trunk_frame(joints: np.ndarray) -> np.ndarray:
    """``(3, 3)`` orthonormal columns: the trunk's up (pelvis centre to neck), across the
    hips (towards the right hip) and their cross product. NaN where degenerate."""
    up, across = _trunk_axes(joints)
    return np.stack([up, across, np.cross(up, across)], axis=1)


def hold_limbs(
    joints: np.ndarray,
    measured: np.ndarray,
    previous: np.ndarray,
    *,
    in_view: np.ndarray,
    previous_in_view: np.ndarray,
    names: tuple[str, ...] = HELD_JOINTS,
) -> np.ndarray:
    """Unseen limb joints placed from their parents as they lay in the last frame.

    A joint of ``names`` that was not measured and lies outside the image (in this
    frame or the last), or whose parent lies outside it in this frame, is put at its
    parent plus its last offset from that parent, turned by the trunk's rotation since
    (:func:`trunk_frame`): its angles to the trunk are held. Each joint is placed after
    its parent.

    Parameters
    ----------
    joints : (15, 3) float
        This frame's skeleton (after :func:`continue_trunk`), all finite.
    measured : (15,) bool
    previous : (15, 3) float
        The last frame's skeleton, all finite.
    in_view, previous_in_view : (15,) bool
        Which joints project inside the image, in this frame and the last.
    names : tuple of str
        The joints that may be held, parents before children.

    Returns
    -------
    (15, 3) float
        A new array; ``joints`` itself where no joint is held or the trunk's rotation
        is unknown.
    """
    held = [
        (j, JOINT_PARENTS[j])
        for j in (_J[name] for name in names)
        if not (measured[j] or (in_view[j] and previous_in_view[j] and in_view[JOINT_PARENTS[j]]))
    ]
    if not held:  # the usual case: no trunk frames to compute
        return joints
    turn = trunk_frame(joints) @ trunk_frame(previous).T
    if not np.isfinite(turn).all():
        return joints
    out = joints.copy()
    for j, parent in held:  # parents first: a held elbow carries its wrist
        out[j] = out[parent] + turn @ (previous[j] - previous[parent])
    return out
