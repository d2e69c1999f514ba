"""Joint conventions: where another skeleton puts the same 15 joints.

Skeletons agree on the names of the joints, not on where they lie: the Kinect v1
SDK's hips sit higher and closer together than the ones recovered here from the
body-part boundaries, its shoulders lower, and so on. These differences are
systematic, so a reference skeleton of another convention is compared fairly once
each recovered joint has been moved by a fixed offset in the person's own frame
(:func:`body_frame`), scaled by the trunk length. The offsets of a convention are
fitted once on development data (:func:`fit_convention`) and then applied to any
new sequence (:func:`to_convention`): no reference enters a conversion.
"""

from __future__ import annotations

from types import MappingProxyType

import numpy as np

from posedrift.skeleton._definitions import JOINT_INDEX, JOINT_NAMES

_J = JOINT_INDEX

# Kinect v1 SDK skeleton (UTD-MHAD's), relative to this package's: per joint, the
# offset (x to the person's left, y up the trunk, z forward; in trunk lengths, neck
# to pelvis centre). Fitted by `python scripts/fit_kinect_convention.py` on the
# development UTD-MHAD sequences (subjects 1-4, trial 1, 108 sequences) from the
# default PoseTracker's output. Cross-validated by subject (fit on two, scored on the
# other two): mAP@10cm 0.63-0.66 -> 0.87, MPJPE 89-92 -> 58-60 mm. Kept when the
# tracker began measuring its limbs over 30 frames: a refit then placed the joints no
# better (cross-validated mAP@10cm 0.874 / 0.878) but moved the elbows 2 cm and
# worsened the converted angles (UTD-MHAD first trials 8.49 -> 8.85 degrees).
_KINECT_OFFSETS = np.array(
    [
        [-0.030, 0.011, -0.035],  # head
        [-0.027, -0.056, -0.013],  # neck
        [0.006, -0.137, -0.001],  # right_shoulder
        [-0.061, -0.165, 0.002],  # left_shoulder
        [-0.019, -0.143, 0.021],  # right_elbow
        [-0.054, -0.189, 0.015],  # left_elbow
        [-0.010, -0.141, 0.049],  # right_hand
        [-0.059, -0.190, 0.058],  # left_hand
        [-0.029, 0.019, 0.017],  # torso
        [0.076, 0.076, 0.039],  # right_hip
        [-0.138, 0.119, 0.054],  # left_hip
        [0.007, -0.021, -0.057],  # right_knee
        [-0.069, 0.059, -0.027],  # left_knee
        [0.030, 0.013, 0.022],  # right_foot
        [-0.065, 0.069, 0.019],  # left_foot
    ]
)
_KINECT_OFFSETS.setflags(write=False)

CONVENTIONS = MappingProxyType(
    {"native": np.zeros((len(JOINT_NAMES), 3)), "kinect": _KINECT_OFFSETS}
)
"""Offsets ``(15, 3)`` of each known convention (see :func:`to_convention`)."""


def body_frame(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The person's own frame and trunk length, from a skeleton.

    Axes: ``x`` from the right to the left hip and shoulder (averaged), ``y`` from the
    pelvis centre up to the neck, ``z = x cross y`` (forward); orthonormal.

    Parameters
    ----------
    joints : (..., 15, 3) float
        Metres, any frame.

    Returns
    -------
    axes : (..., 3, 3) float
        Rows are the unit ``x``, ``y``, ``z`` axes in the input frame; NaN where
        the hips, shoulders or neck are unknown or degenerate.
    trunk : (...) float
        Distance from the pelvis centre to the neck, metres.
    """
    j = np.asarray(joints, dtype=float)
    pelvis = 0.5 * (j[..., _J["left_hip"], :] + j[..., _J["right_hip"], :])
    up = j[..., _J["neck"], :] - pelvis
    trunk = np.linalg.norm(up, axis=-1)
    across = (
        j[..., _J["left_hip"], :]
        - j[..., _J["right_hip"], :]
        + j[..., _J["left_shoulder"], :]
        - j[..., _J["right_shoulder"], :]
    )
    with np.errstate(invalid="ignore", divide="ignore"):
        y = up / trunk[..., None]
        x = across - np.sum(across * y, axis=-1, keepdims=True) * y
        x = x / np.linalg.norm(x, axis=-1, keepdims=True)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=-2), trunk


def to_convention(joints: np.ndarray, convention: str = "kinect") -> np.ndarray:
    """Move recovered joints to where another skeleton convention puts them.

    Parameters
    ----------
    joints : (..., 15, 3) float
        Recovered joints (this package's convention), metres.
    convention : str
        A key of :data:`CONVENTIONS`: ``"native"`` (unchanged) or ``"kinect"``
        (the Kinect v1 SDK skeleton, as in UTD-MHAD).

    Returns
    -------
    (..., 15, 3) float
        NaN where the body frame is unknown.

    Examples
    --------
    >>> from posedrift.skeleton import t_pose_joints
    >>> joints = t_pose_joints(1.75)
    >>> bool(np.array_equal(to_convention(joints, "native"), joints))
    True
    >>> moved = to_convention(joints, "kinect")
    >>> bool(moved[JOINT_INDEX["right_hip"], 1] > joints[JOINT_INDEX["right_hip"], 1])
    True
    """
    if convention not in CONVENTIONS:
        raise ValueError(
            f"Unknown joint convention {convention!r}: expected one of {sorted(CONVENTIONS)}."
        )
    joints = np.asarray(joints, dtype=float)
    if joints.shape[-2:] != (len(JOINT_NAMES), 3):
        raise ValueError(f"'joints' must be (..., 15, 3). Got {joints.shape}.")
    if convention == "native":
        return joints.copy()
    axes, trunk = body_frame(joints)
    offsets = np.einsum("...ab,ja->...jb", axes, CONVENTIONS[convention])
    return joints + offsets * trunk[..., None, None]


def fit_convention(estimates: np.ndarray, references: np.ndarray) -> np.ndarray:
    """Offsets ``(15, 3)`` that take recovered joints to a reference convention.

    The median, over frames where both skeletons are known, of each reference
    joint's offset from the recovered one, in the recovered skeleton's body frame
    and trunk lengths (what :func:`to_convention` applies).

    Parameters
    ----------
    estimates, references : (T, 15, 3) float
        The same frames, metres.

    Returns
    -------
    (15, 3) float
    """
    est = np.asarray(estimates, dtype=float)
    ref = np.asarray(references, dtype=float)
    if est.shape != ref.shape or est.shape[-2:] != (len(JOINT_NAMES), 3) or est.ndim != 3:
        raise ValueError(
            "'estimates' and 'references' must both be (T, 15, 3). "
            f"Got {est.shape} and {ref.shape}."
        )
    axes, trunk = body_frame(est)
    ok = (
        np.isfinite(est).all(axis=(1, 2))
        & np.isfinite(ref).all(axis=(1, 2))
        & np.isfinite(axes).all(axis=(1, 2))
        & (trunk > 1e-6)
    )
    if not ok.any():
        raise ValueError("fit_convention needs at least one frame where both skeletons are known.")
    local = np.einsum("tab,tjb->tja", axes[ok], ref[ok] - est[ok]) / trunk[ok, None, None]
    return np.median(local, axis=0)
