"""UTD-MHAD: real Kinect v1 depth sequences with the Kinect SDK skeleton as reference.

Chen, Jafari and Kehtarnavaz, "UTD-MHAD: A multimodal dataset for human action
recognition utilizing a depth camera and a wearable inertial sensor", ICIP 2015,
doi:10.1109/ICIP.2015.7350781.

The depth images are mirrored (the person's left arm appears on the image's left,
as in a mirror) and the skeleton is in the Kinect SDK's skeleton space (metres,
+X to the sensor's left, +Y up, +Z forward), for which ``u = cx + f X / Z`` and
``v = cy - f Y / Z``. A method that was trained on true (unmirrored) geometry
would call the person's left arm its right, so the loader un-mirrors by default:
it flips the image columns, takes ``cx' = (W - 1) - cx``, and maps the skeleton
to the camera frame as ``(-X, -Y, Z)``. Back-projecting the flipped image with
``cx'`` gives exactly the mirror image of the raw back-projection, so the
reference still lands on the person (checked in ``tests/test_utd.py``).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics, camera_preset
from posedrift.evaluation._types import EvaluationSequence, Reference
from posedrift.skeleton import JOINT_INDEX, JOINT_NAMES, joint_angles

KINECT20_NAMES: tuple[str, ...] = (
    "head",
    "shoulder_center",
    "spine",
    "hip_center",
    "left_shoulder",
    "left_elbow",
    "left_wrist",
    "left_hand",
    "right_shoulder",
    "right_elbow",
    "right_wrist",
    "right_hand",
    "left_hip",
    "left_knee",
    "left_ankle",
    "left_foot",
    "right_hip",
    "right_knee",
    "right_ankle",
    "right_foot",
)
"""The Kinect v1 SDK's 20 joints in UTD-MHAD's order (``Skeleton_joint_order.txt``)."""

KINECT20_TO_15: dict[str, str] = {
    "head": "head",
    "neck": "shoulder_center",
    "right_shoulder": "right_shoulder",
    "left_shoulder": "left_shoulder",
    "right_elbow": "right_elbow",
    "left_elbow": "left_elbow",
    "right_hand": "right_wrist",
    "left_hand": "left_wrist",
    "right_hip": "right_hip",
    "left_hip": "left_hip",
    "right_knee": "right_knee",
    "left_knee": "left_knee",
    "right_foot": "right_ankle",
    "left_foot": "left_ankle",
}
"""Joint map of ``METHOD.md`` section 5; ``torso`` is computed (neck and pelvis midpoint)."""

_NAME = re.compile(r"^(a\d+_s\d+_t\d+)_(depth|skeleton)\.mat$")


def kinect20_to_joints(skeleton: np.ndarray, *, unmirror: bool = True) -> np.ndarray:
    """Map Kinect-20 skeleton-space joints to the 15 joints in the camera frame.

    Parameters
    ----------
    skeleton : (T, 20, 3) float
        Kinect SDK skeleton space, metres (+X sensor's left, +Y up, +Z forward).
        All-zero frames (the SDK's "not tracked") become NaN.
    unmirror : bool
        ``True`` for the un-mirrored camera frame ``(-X, -Y, Z)``; ``False`` for
        the frame of the raw (mirrored) image, ``(X, -Y, Z)``.

    Returns
    -------
    joints : (T, 15, 3) float
        Metres, camera frame (+X right, +Y down, +Z forward), ``JOINT_NAMES`` order.
    """
    skeleton = np.asarray(skeleton, dtype=float)
    if skeleton.ndim != 3 or skeleton.shape[1:] != (20, 3):
        raise ValueError(
            f"The 'skeleton' argument of kinect20_to_joints must have shape (T, 20, 3). "
            f"Got shape {skeleton.shape} instead."
        )
    sign = np.array([-1.0 if unmirror else 1.0, -1.0, 1.0])
    camera = skeleton * sign
    untracked = ~np.any(skeleton != 0, axis=(1, 2)) | ~np.isfinite(skeleton).all(axis=(1, 2))
    camera[untracked] = np.nan
    out = np.full((len(skeleton), len(JOINT_NAMES), 3), np.nan)
    kidx = {name: i for i, name in enumerate(KINECT20_NAMES)}
    for ours, theirs in KINECT20_TO_15.items():
        out[:, JOINT_INDEX[ours]] = camera[:, kidx[theirs]]
    pelvis = 0.5 * (out[:, JOINT_INDEX["right_hip"]] + out[:, JOINT_INDEX["left_hip"]])
    out[:, JOINT_INDEX["torso"]] = 0.5 * (out[:, JOINT_INDEX["neck"]] + pelvis)
    return out


def _load_mat(path: Path, key: str, what: str) -> np.ndarray:
    from scipy.io import loadmat

    if not path.is_file():
        raise ValueError(f"The UTD-MHAD {what} file {str(path)!r} does not exist.")
    try:
        data = loadmat(str(path))
    except Exception as exc:  # scipy raises several types for a damaged file
        raise ValueError(f"Cannot read the UTD-MHAD {what} file {str(path)!r}: {exc}") from exc
    if key not in data:
        keys = sorted(k for k in data if not k.startswith("__"))
        raise ValueError(
            f"The UTD-MHAD {what} file {str(path)!r} has no {key!r} array. Got keys {keys}."
        )
    return np.asarray(data[key])


def load_utd_sequence(
    depth_path: str | Path,
    skeleton_path: str | Path,
    *,
    intrinsics: Intrinsics | None = None,
    unmirror: bool = True,
    name: str | None = None,
) -> EvaluationSequence:
    """Load one UTD-MHAD sequence: depth frames for the methods, Kinect joints as reference.

    Parameters
    ----------
    depth_path : path
        ``a{action}_s{subject}_t{trial}_depth.mat`` (key ``d_depth``, ``(240, 320, T)``
        uint16 millimetres, background zero).
    skeleton_path : path
        The matching ``..._skeleton.mat`` (key ``d_skel``, ``(20, 3, T)`` metres).
    intrinsics : Intrinsics, optional
        Of the raw images; nominal Kinect v1 at QVGA (``kinect1-qvga``) by default.
    unmirror : bool
        Flip the mirrored images (and the reference) to true geometry (see the
        module docstring). The frames then carry ``cx' = (W - 1) - cx``.
    name : str, optional
        The sequence name; by default the file name without ``_depth.mat``.

    Returns
    -------
    EvaluationSequence
        At 30 fps, with ``reference.kind == "kinect"`` and no label images.
        A skeleton longer than the depth is cut to the depth's length.

    Raises
    ------
    ValueError
        If a file is missing or unreadable, an array has the wrong shape, or the
        skeleton has fewer frames than the depth (the message names the file).
    """
    depth_path = Path(depth_path)
    skeleton_path = Path(skeleton_path)
    k = camera_preset("kinect1-qvga") if intrinsics is None else intrinsics
    if name is None:
        name = depth_path.name.removesuffix(".mat").removesuffix("_depth")
    depth = _load_mat(depth_path, "d_depth", "depth")
    if depth.ndim != 3 or depth.shape[:2] != k.shape:
        raise ValueError(
            f"The UTD-MHAD depth file {str(depth_path)!r} must hold a {k.shape[0]} x {k.shape[1]}"
            f" x T array 'd_depth'. Got shape {depth.shape}."
        )
    skel = _load_mat(skeleton_path, "d_skel", "skeleton")
    if skel.ndim != 3 or skel.shape[:2] != (20, 3):
        raise ValueError(
            f"The UTD-MHAD skeleton file {str(skeleton_path)!r} must hold a 20 x 3 x T array "
            f"'d_skel'. Got shape {skel.shape}."
        )
    n = depth.shape[2]
    if skel.shape[2] < n:
        raise ValueError(
            f"The UTD-MHAD skeleton file {str(skeleton_path)!r} has {skel.shape[2]} frames, "
            f"fewer than the {n} depth frames of {str(depth_path)!r}."
        )
    joints = kinect20_to_joints(np.transpose(skel[:, :, :n], (2, 0, 1)), unmirror=unmirror)
    if unmirror:
        k = Intrinsics(
            fx=k.fx, fy=k.fy, cx=(k.width - 1) - k.cx, cy=k.cy, width=k.width, height=k.height
        )
    frames = []
    for t in range(n):
        raw = depth[:, ::-1, t] if unmirror else depth[:, :, t]
        frames.append(
            DepthFrame.from_raw(
                np.ascontiguousarray(raw),
                k,
                depth_scale=1000.0,
                index=t,
                timestamp=t / 30.0,
                source=f"{depth_path.name}",
            )
        )
    reference = Reference(joints=joints, angles=joint_angles(joints), labels=None, kind="kinect")
    return EvaluationSequence(name=name, frames=tuple(frames), reference=reference, fps=30.0)


def find_utd_sequences(
    root: str | Path,
) -> tuple[list[tuple[str, Path, Path]], list[tuple[str, str]]]:
    """Pair the depth and skeleton files of a UTD-MHAD folder.

    Parameters
    ----------
    root : path
        A folder holding ``Depth/`` and ``Skeleton/`` (or the files side by side).

    Returns
    -------
    found : list of (name, depth_path, skeleton_path)
        Sorted by action, subject and trial.
    skipped : list of (name, reason)
        Depth files without a skeleton file.

    Raises
    ------
    ValueError
        If ``root`` is not a folder or holds no depth files.
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"The UTD-MHAD folder {str(root)!r} does not exist.")
    depth_dir = root / "Depth" if (root / "Depth").is_dir() else root
    skel_dir = root / "Skeleton" if (root / "Skeleton").is_dir() else root
    found: list[tuple[str, Path, Path]] = []
    skipped: list[tuple[str, str]] = []
    for path in depth_dir.glob("*_depth.mat"):
        match = _NAME.match(path.name)
        if not match:
            continue
        name = match.group(1)
        skel = skel_dir / f"{name}_skeleton.mat"
        if skel.is_file():
            found.append((name, path, skel))
        else:
            skipped.append((name, f"no skeleton file {str(skel)!r}"))
    if not found and not skipped:
        raise ValueError(
            f"The UTD-MHAD folder {str(root)!r} holds no 'a*_s*_t*_depth.mat' files "
            f"(looked in {str(depth_dir)!r})."
        )

    def key(item: tuple) -> tuple[int, ...]:
        return tuple(int(v) for v in re.findall(r"\d+", item[0]))

    return sorted(found, key=key), sorted(skipped, key=key)
