"""Error metrics of the paper's Table 1 and of ITOP: angle errors, MPJPE, mAP@10cm.

Conventions (``METHOD.md`` section 2): angles in degrees in ``ANGLE_NAMES`` order,
joints in metres in ``JOINT_NAMES`` order. A frame where a method returned no pose
(NaN joints) is a *failed* frame: it is left out of every error mean here and
counted separately (:func:`failed_frames`); :func:`fill_forward` gives the
alternative that fills it with the last known pose.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from posedrift._validation import check_scalar
from posedrift.camera import Intrinsics, project
from posedrift.skeleton import ANGLE_JOINTS, ANGLE_NAMES, JOINT_INDEX, JOINT_NAMES


def _check_same_shape(est: np.ndarray, ref: np.ndarray, shape: tuple, caller: str) -> None:
    for name, arr in (("est", est), ("ref", ref)):
        if arr.ndim != len(shape) or arr.shape[1:] != shape[1:]:
            wanted = "(T, " + ", ".join(str(s) for s in shape[1:]) + ")"
            raise ValueError(
                f"The '{name}' argument of {caller} must have shape {wanted}. "
                f"Got shape {arr.shape} instead."
            )
    if est.shape != ref.shape:
        raise ValueError(
            f"The 'est' and 'ref' arguments of {caller} must have the same number of frames. "
            f"Got {est.shape[0]} and {ref.shape[0]}."
        )


def angle_errors(est_angles: np.ndarray, ref_angles: np.ndarray) -> dict[str, float | None]:
    """Mean absolute angle error per angle (Eq. 2 of the paper) and their mean.

    Parameters
    ----------
    est_angles, ref_angles : (T, 8) float
        Degrees, in :data:`posedrift.skeleton.ANGLE_NAMES` order; NaN where unknown.

    Returns
    -------
    errors : dict
        ``{angle_name: degrees, ..., "mean": degrees}``. Each angle's error is the
        mean of ``|est - ref|`` over the frames where both are known (None where
        there is no such frame); ``"mean"`` is the mean of the eight per-angle
        errors (of those that are known).

    Examples
    --------
    >>> import numpy as np
    >>> est = np.full((2, 8), 90.0); ref = est.copy(); ref[0, 0] = 80.0
    >>> angle_errors(est, ref)["left_elbow"], angle_errors(est, ref)["mean"]
    (5.0, 0.625)
    """
    est = np.asarray(est_angles, dtype=float)
    ref = np.asarray(ref_angles, dtype=float)
    _check_same_shape(est, ref, (0, len(ANGLE_NAMES)), "angle_errors")
    diff = np.abs(est - ref)
    out: dict[str, float | None] = {}
    known = []
    for k, name in enumerate(ANGLE_NAMES):
        d = diff[:, k]
        d = d[np.isfinite(d)]
        if d.size:
            out[name] = float(d.mean())
            known.append(out[name])
        else:
            out[name] = None
    out["mean"] = float(np.mean(known)) if known else None
    return out


def angle_agreement(est_angles: np.ndarray, ref_angles: np.ndarray) -> dict[str, dict]:
    """Bland-Altman agreement of each angle with the reference: bias and 95% limits.

    A mean absolute error mixes a constant offset with frame-to-frame scatter; a
    clinician comparing a measuring tool against a reference asks for them apart
    (Bland and Altman, Lancet 1986). Per angle: ``bias_deg``, the mean signed
    difference ``est - ref`` (positive: the estimate reads the joint straighter, or
    the limb further from the trunk, than it is); ``sd_deg``, the differences'
    sample standard deviation; ``loa_low_deg`` and ``loa_high_deg``, the limits of
    agreement ``bias -/+ 1.96 sd``, between which about 95% of the differences lie;
    ``frames``, how many frames had both angles. Values are None where fewer than
    two frames did.

    Parameters
    ----------
    est_angles, ref_angles : (T, 8) float
        Degrees, in :data:`posedrift.skeleton.ANGLE_NAMES` order; NaN where unknown.

    Returns
    -------
    agreement : dict
        ``{angle_name: {"bias_deg", "sd_deg", "loa_low_deg", "loa_high_deg", "frames"}}``.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.full((4, 8), 90.0); est = ref + [[1.0], [3.0], [1.0], [3.0]]
    >>> row = angle_agreement(est, ref)["left_elbow"]
    >>> row["bias_deg"], round(row["sd_deg"], 3), row["frames"]
    (2.0, 1.155, 4)
    """
    est = np.asarray(est_angles, dtype=float)
    ref = np.asarray(ref_angles, dtype=float)
    _check_same_shape(est, ref, (0, len(ANGLE_NAMES)), "angle_agreement")
    out: dict[str, dict] = {}
    for k, name in enumerate(ANGLE_NAMES):
        d = est[:, k] - ref[:, k]
        d = d[np.isfinite(d)]
        row: dict = dict.fromkeys(("bias_deg", "sd_deg", "loa_low_deg", "loa_high_deg"))
        if d.size >= 2:
            bias, sd = float(d.mean()), float(d.std(ddof=1))
            half = 1.96 * sd  # the 97.5% quantile of a normal spread
            row.update(bias_deg=bias, sd_deg=sd, loa_low_deg=bias - half, loa_high_deg=bias + half)
        out[name] = {**row, "frames": int(d.size)}
    return out


def joint_errors_m(est: np.ndarray, ref: np.ndarray) -> np.ndarray:
    """Euclidean distance per frame and joint, ``(T, 15)`` metres, NaN where either is unknown."""
    est = np.asarray(est, dtype=float)
    ref = np.asarray(ref, dtype=float)
    _check_same_shape(est, ref, (0, len(JOINT_NAMES), 3), "joint_errors_m")
    return np.linalg.norm(est - ref, axis=-1)


def mpjpe_mm(est: np.ndarray, ref: np.ndarray) -> float | None:
    """Mean per-joint position error in millimetres.

    Parameters
    ----------
    est, ref : (T, 15, 3) float
        Joints in metres, the same frame and joint order; NaN where unknown.

    Returns
    -------
    float or None
        Mean Euclidean distance over all (frame, joint) pairs where both are
        known, in millimetres; None if there is none.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.zeros((1, 15, 3)); est = ref.copy(); est[..., 0] = 0.01
    >>> round(mpjpe_mm(est, ref), 6)
    10.0
    """
    d = joint_errors_m(est, ref)
    d = d[np.isfinite(d)]
    return float(d.mean() * 1000.0) if d.size else None


def map_at(est: np.ndarray, ref: np.ndarray, threshold: float = 0.10) -> float | None:
    """Mean average precision at a distance threshold, as on ITOP.

    For each joint, the share of frames (where both are known) whose estimate
    lies within ``threshold`` metres of the reference; then the mean over joints.

    Parameters
    ----------
    est, ref : (T, 15, 3) float
        Joints in metres; NaN where unknown.
    threshold : float
        Metres (0.10 for mAP@10cm).

    Returns
    -------
    float or None
        In [0, 1]; None if no joint is known anywhere.

    Examples
    --------
    >>> import numpy as np
    >>> ref = np.zeros((2, 15, 3)); est = ref.copy(); est[0, :, 0] = 0.2
    >>> map_at(est, ref)
    0.5
    """
    if not threshold > 0:
        raise ValueError(
            f"The 'threshold' parameter of map_at must be a positive distance in metres. "
            f"Got {threshold!r} instead."
        )
    d = joint_errors_m(est, ref)
    known = np.isfinite(d)
    per_joint = []
    for j in range(d.shape[1]):
        col = d[known[:, j], j]
        if col.size:
            per_joint.append(float(np.mean(col < threshold)))
    return float(np.mean(per_joint)) if per_joint else None


def _joints_in_image(ref: np.ndarray, intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """``(T, 15)`` bool where each joint projects into the image, and ``(T, 15, 2)`` its pixel."""
    known = np.isfinite(ref).all(axis=-1)
    flat = np.where(known[..., None], ref, [0.0, 0.0, 1.0]).reshape(-1, 3)
    uv = project(flat, intrinsics).reshape(*ref.shape[:2], 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        inside = (
            known
            & (ref[..., 2] > 0)
            & (uv[..., 0] >= 0)
            & (uv[..., 0] < intrinsics.width)
            & (uv[..., 1] >= 0)
            & (uv[..., 1] < intrinsics.height)
        )
    return inside, uv


def _per_angle(joints_ok: np.ndarray) -> np.ndarray:
    """``(T, 8)``: where every joint an angle is computed from is ``joints_ok``."""
    columns = [
        joints_ok[:, [JOINT_INDEX[j] for j in ANGLE_JOINTS[a]]].all(axis=1) for a in ANGLE_NAMES
    ]
    return np.stack(columns, axis=1)


def angles_in_view(ref: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """``(T, 8)`` bool: where every joint an angle is computed from lies in the image.

    A joint outside the image (or behind the camera) leaves nothing in the depth
    frame to measure it by, so an error on such an angle scores a guess: a
    climber's raised arms above the top of the view, the feet below its bottom.
    The joints of each angle are :data:`posedrift.skeleton.ANGLE_JOINTS`; a joint
    is in the image where it projects into ``[0, width) x [0, height)``.
    :func:`angles_seen` also asks that nothing hides the joints.

    Parameters
    ----------
    ref : (T, 15, 3) float
        The reference joints, camera frame, metres.
    intrinsics : Intrinsics
        The camera that rendered or recorded the frames.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import Intrinsics
    >>> from posedrift.skeleton import t_pose_joints
    >>> joints = t_pose_joints(1.75) * [1.0, -1.0, -1.0] + [0.0, 0.9, 3.0]  # camera frame
    >>> kinect = Intrinsics(fx=285.63, fy=285.63, cx=160.0, cy=120.0, width=320, height=240)
    >>> angles_in_view(joints[None], kinect).all()
    np.True_
    >>> angles_in_view(joints[None] - [0.0, 0.8, 0.0], kinect)[0].tolist()  # shoulders cut off
    [False, False, False, False, True, True, False, False]
    """
    ref = np.asarray(ref, dtype=float)
    _check_same_shape(ref, ref, (0, len(JOINT_NAMES), 3), "angles_in_view")
    return _per_angle(_joints_in_image(ref, intrinsics)[0])


SEEN_TOLERANCE = 0.20
"""Metres the depth image's surface may lie in front of a joint with the joint still
seen. A joint lies under its own body's surface: facing the camera in the calibration
pose, the rendered default body's torso joint lies 13 cm behind the surface at its pixel
(a short, wide body's 15), the hips 12 (14), the head 10-12, the shoulders 6-8, the
elbows, knees and ankles 4-6 and the wrists 2-3. What hides a joint stands further in
front: a forearm pointed at the camera covers its elbow from its length, 25-30 cm, and a
trunk seen side-on its far shoulder from about the shoulders' width."""


def joints_seen(
    ref: np.ndarray,
    depth: Sequence[np.ndarray],
    intrinsics: Intrinsics,
    *,
    tolerance: float = SEEN_TOLERANCE,
) -> np.ndarray:
    """``(T, 15)`` bool: where the camera sees each reference joint.

    A joint is seen where it lies in the image (as in :func:`angles_in_view`) and
    nothing stands between it and the camera: the median depth of the readings in
    the 3 x 3 pixels around its projection lies no more than ``tolerance`` in
    front of it. A forearm pointed at the camera hides its elbow, an arm across the
    chest the trunk's joints behind it, a body turned side-on its far shoulder;
    there the frame holds no surface of the joint to measure it by. A joint with
    no reading around its pixel (the silhouette's edge) counts as seen.

    Parameters
    ----------
    ref : (T, 15, 3) float
        The reference joints, camera frame, metres.
    depth : sequence of T (H, W) float arrays
        The frames' depth images, metres; zero or non-finite where there is no
        reading.
    intrinsics : Intrinsics
        The camera that rendered or recorded the frames.
    tolerance : float
        Metres; see :data:`SEEN_TOLERANCE`.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import Intrinsics
    >>> from posedrift.skeleton import JOINT_INDEX, t_pose_joints
    >>> camera = Intrinsics(fx=285.63, fy=285.63, cx=160.0, cy=120.0, width=320, height=240)
    >>> joints = t_pose_joints(1.75) * [1.0, -1.0, -1.0] + [0.0, 0.9, 3.0]
    >>> wall = np.full((240, 320), 3.05)  # a surface 5 cm behind the body's plane
    >>> joints_seen(joints[None], [wall], camera).all()
    np.True_
    >>> board = np.full((240, 320), 2.7)  # something 30 cm in front of every joint
    >>> joints_seen(joints[None], [board], camera)[0, JOINT_INDEX["left_elbow"]]
    np.False_
    """
    ref = np.asarray(ref, dtype=float)
    _check_same_shape(ref, ref, (0, len(JOINT_NAMES), 3), "joints_seen")
    tolerance = check_scalar(
        tolerance, "tolerance", low=0.0, include_low=True, caller="joints_seen"
    )
    if len(depth) != len(ref):
        raise ValueError(
            f"The 'depth' argument of joints_seen must hold one image per reference frame "
            f"({len(ref)}). Got {len(depth)}."
        )
    inside, uv = _joints_in_image(ref, intrinsics)
    seen = inside.copy()
    steps = np.arange(-1, 2)
    for t, image in enumerate(depth):
        image = np.asarray(image, dtype=float)
        if image.shape != intrinsics.shape:
            raise ValueError(
                f"Depth image {t} given to joints_seen has shape {image.shape}; the "
                f"intrinsics say {intrinsics.shape}."
            )
        joints = np.flatnonzero(inside[t])
        cols = np.rint(uv[t, joints, 0]).astype(np.intp)
        rows = np.rint(uv[t, joints, 1]).astype(np.intp)
        r = np.clip(rows[:, None, None] + steps[:, None], 0, intrinsics.height - 1)
        c = np.clip(cols[:, None, None] + steps[None, :], 0, intrinsics.width - 1)
        window = image[r, c].reshape(len(joints), -1)
        window[~(np.isfinite(window) & (window > 0))] = np.nan
        read = np.isfinite(window).any(axis=1)
        surface = np.full(len(joints), np.inf)
        surface[read] = np.nanmedian(window[read], axis=1)
        seen[t, joints] = surface >= ref[t, joints, 2] - tolerance
    return seen


def angles_seen(
    ref: np.ndarray,
    depth: Sequence[np.ndarray],
    intrinsics: Intrinsics,
    *,
    tolerance: float = SEEN_TOLERANCE,
) -> np.ndarray:
    """``(T, 8)`` bool: where the camera sees every joint an angle is computed from.

    :func:`joints_seen` per joint, then :data:`posedrift.skeleton.ANGLE_JOINTS`;
    the parameters are :func:`joints_seen`'s. An error on an angle that is not
    seen scores how well a method guesses what the frame does not show.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import Intrinsics
    >>> from posedrift.skeleton import JOINT_INDEX, t_pose_joints
    >>> camera = Intrinsics(fx=285.63, fy=285.63, cx=160.0, cy=120.0, width=320, height=240)
    >>> joints = t_pose_joints(1.75) * [1.0, -1.0, -1.0] + [0.0, 0.9, 3.0]
    >>> depth = np.full((240, 320), 3.05)
    >>> angles_seen(joints[None], [depth], camera)[0].all()
    np.True_
    >>> joints[JOINT_INDEX["left_elbow"], 2] += 0.3  # the elbow 30 cm behind the surface
    >>> angles_seen(joints[None], [depth], camera)[0].tolist()
    [False, True, False, True, True, True, True, True]
    """
    return _per_angle(joints_seen(ref, depth, intrinsics, tolerance=tolerance))


def failed_frames(est: np.ndarray) -> np.ndarray:
    """``(T,)`` bool: frames whose joints are not all known (the method returned no pose)."""
    est = np.asarray(est, dtype=float)
    return ~np.isfinite(est.reshape(len(est), -1)).all(axis=1)


def fill_forward(est: np.ndarray) -> np.ndarray:
    """Replace each failed frame by the last known pose (frames before the first stay NaN).

    Parameters
    ----------
    est : (T, ...) float
        Per-frame values (joints ``(T, 15, 3)`` or angles ``(T, 8)``).

    Examples
    --------
    >>> import numpy as np
    >>> fill_forward(np.array([[np.nan], [1.0], [np.nan], [3.0]])).ravel().tolist()
    [nan, 1.0, 1.0, 3.0]
    """
    out = np.array(est, dtype=float, copy=True)
    bad = ~np.isfinite(out.reshape(len(out), -1)).all(axis=1)
    last = None
    for t in range(len(out)):
        if bad[t]:
            if last is not None:
                out[t] = out[last]
        else:
            last = t
    return out
