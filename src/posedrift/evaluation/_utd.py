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
import warnings
from collections.abc import Callable, Iterable
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

_NAME = re.compile(r"^(a\d+_s\d+_t\d+)_(depth|skeleton)\.mat$", re.IGNORECASE)
"""UTD-MHAD's file names, ``a{action}_s{subject}_t{trial}_{depth|skeleton}.mat``, any case."""


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
        The sequence name; by default the file name without ``_depth.mat`` (any case).

    Returns
    -------
    EvaluationSequence
        At 30 fps, with ``reference.kind == "kinect"`` and no label images.
        A skeleton longer than the depth is cut to the depth's length.

    Raises
    ------
    ValueError
        If a file is missing or unreadable, an array has the wrong shape or no
        frames, the skeleton has fewer frames than the depth, or no frame of the
        skeleton is tracked (all zeros or not finite): the message names the file.
    """
    depth_path = Path(depth_path)
    skeleton_path = Path(skeleton_path)
    k = camera_preset("kinect1-qvga") if intrinsics is None else intrinsics
    if name is None:
        name = depth_path.name
        name = name[: -len("_depth.mat")] if name.lower().endswith("_depth.mat") else name
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
    if n == 0:
        raise ValueError(
            f"The UTD-MHAD depth file {str(depth_path)!r} holds no frames ('d_depth' of shape "
            f"{depth.shape})."
        )
    if skel.shape[2] == 0:
        raise ValueError(
            f"The UTD-MHAD skeleton file {str(skeleton_path)!r} holds no frames ('d_skel' of "
            f"shape {skel.shape})."
        )
    if skel.shape[2] < n:
        raise ValueError(
            f"The UTD-MHAD skeleton file {str(skeleton_path)!r} has {skel.shape[2]} frames, "
            f"fewer than the {n} depth frames of {str(depth_path)!r}."
        )
    joints = kinect20_to_joints(np.transpose(skel[:, :, :n], (2, 0, 1)), unmirror=unmirror)
    if not np.isfinite(joints).all(axis=(1, 2)).any():
        raise ValueError(
            f"The UTD-MHAD skeleton file {str(skeleton_path)!r} has no usable frame among its "
            f"first {n}: every one is all zeros (the SDK's 'not tracked') or not finite."
        )
    if unmirror:
        k = Intrinsics(
            fx=k.fx, fy=k.fy, cx=(k.width - 1) - k.cx, cy=k.cy, width=k.width, height=k.height
        )
    # UTD-MHAD stores millimetres as integers; floating-point depth is metres, as for
    # every other posedrift reader.
    scale = 1000.0 if np.issubdtype(depth.dtype, np.integer) else 1.0
    frames = []
    for t in range(n):
        raw = depth[:, ::-1, t] if unmirror else depth[:, :, t]
        frames.append(
            DepthFrame.from_raw(
                np.ascontiguousarray(raw),
                k,
                depth_scale=scale,
                index=t,
                timestamp=t / 30.0,
                source=f"{depth_path.name}",
            )
        )
    reference = Reference(joints=joints, angles=joint_angles(joints), labels=None, kind="kinect")
    return EvaluationSequence(name=name, frames=tuple(frames), reference=reference, fps=30.0)


def _sort_key(name: str) -> tuple[tuple[int, ...], str]:
    """Action, subject, trial (the numbers in the name), then the name itself."""
    return tuple(int(v) for v in re.findall(r"\d+", name)), name


def _mat_files(folder: Path, kind: str) -> list[Path]:
    """Entries of ``folder`` named ``*_{kind}.mat`` in any case (broken links included)."""
    suffix = f"_{kind}.mat"
    return sorted(p for p in folder.iterdir() if p.name.lower().endswith(suffix) and not p.is_dir())


def _stem(path: Path, kind: str) -> str:
    """The file name without ``_{kind}.mat``."""
    return path.name[: -len(f"_{kind}.mat")]


def _warn_ignored(item: str, reason: str) -> None:
    warnings.warn(f"{item}: {reason}", RuntimeWarning, stacklevel=3)


def find_utd_sequences(
    root: str | Path,
    *,
    names: Iterable[str] | None = None,
    limit: int | None = None,
    on_ignored: Callable[[str, str], None] | None = None,
) -> tuple[list[tuple[str, Path, Path]], list[tuple[str, str]]]:
    """Pair the depth and skeleton files of a UTD-MHAD folder.

    A sequence is named after its depth file, without ``_depth.mat``. Without
    ``names``, the sequences are the depth files that follow UTD-MHAD's pattern
    ``a{action}_s{subject}_t{trial}_depth.mat`` in any case (``A1_S1_T1_depth.mat``
    is the sequence ``A1_S1_T1``). Files ending in ``_depth.mat`` or ``_skeleton.mat``
    whose names do not follow it (``a5_s1_t1 (copy)_depth.mat``: often a stray copy
    that would count a clip twice), and skeleton files without a depth file, are
    not sequences: each is reported once through ``on_ignored`` and left out.
    Asking for such a file by name (``names=["a5_s1_t1 (copy)"]``) evaluates it.

    Each depth file is paired with the skeleton file of the same name spelled the
    same way, or else in any case.

    Parameters
    ----------
    root : path
        A folder holding ``Depth/`` and ``Skeleton/`` (or the files side by side).
    names : iterable of str, optional
        Only these sequences, in this order, whatever their pattern; a name is
        matched in any case when no depth file has exactly that spelling. A repeated
        name, or two names of one file, count once (each repeated name is reported
        once through ``on_ignored``). A name without a depth file is skipped. Files that were not
        asked for are not reported.
    limit : int, optional
        Only the first ``limit`` sequences of that order, whether they pair or not.
    on_ignored : callable, optional
        ``on_ignored(item, reason)`` for each file left out and each repeated name
        (``item`` is the file's path or the name); by default a ``RuntimeWarning``.

    Returns
    -------
    found : list of (name, depth_path, skeleton_path)
        Sorted by action, subject and trial (in the order of ``names`` when given).
    skipped : list of (name, reason)
        Selected sequences that cannot be paired: a depth file without a skeleton
        file, or a name in ``names`` without a depth file ("no such sequence in the
        folder"). In the same order.

    Raises
    ------
    ValueError
        If ``root`` is not a folder, or holds no ``a*_s*_t*_depth.mat`` files
        (with ``names``: no ``*_depth.mat`` files at all).
    """
    root = Path(root)
    if not root.is_dir():
        raise ValueError(f"The UTD-MHAD folder {str(root)!r} does not exist.")
    if limit is not None and limit < 1:
        raise ValueError(f"The 'limit' argument must be at least 1. Got {limit}.")
    report = _warn_ignored if on_ignored is None else on_ignored
    depth_dir = root / "Depth" if (root / "Depth").is_dir() else root
    skel_dir = root / "Skeleton" if (root / "Skeleton").is_dir() else root
    depth_files = _mat_files(depth_dir, "depth")
    skel_files = _mat_files(skel_dir, "skeleton")
    skel_set = set(skel_files)
    skel_by_key: dict[str, list[Path]] = {}
    for path in skel_files:
        skel_by_key.setdefault(_stem(path, "skeleton").casefold(), []).append(path)

    def skeleton_of(name: str) -> tuple[Path | None, str | None]:
        exact = skel_dir / f"{name}_skeleton.mat"
        if exact in skel_set:
            return exact, None
        candidates = skel_by_key.get(name.casefold(), [])
        if len(candidates) == 1:
            return candidates[0], None
        if candidates:
            listed = ", ".join(repr(p.name) for p in candidates)
            return None, f"several skeleton files match it in case ({listed}), none exactly"
        return None, f"no skeleton file {str(exact)!r}"

    def pair(path: Path) -> tuple[str, Path, Path | None, str | None]:
        stem = _stem(path, "depth")
        return (stem, path, *skeleton_of(stem))

    entries: list[tuple[str, Path | None, Path | None, str | None]] = []
    pattern = "a<action>_s<subject>_t<trial>"
    if names is None:
        odd = [p for p in depth_files if not _NAME.match(p.name)]
        entries = [pair(p) for p in depth_files if _NAME.match(p.name)]
        if not entries:
            others = f"; other names: {', '.join(repr(p.name) for p in odd)}" if odd else ""
            raise ValueError(
                f"The UTD-MHAD folder {str(root)!r} holds no 'a*_s*_t*_depth.mat' files "
                f"(looked in {str(depth_dir)!r}{others})."
            )
        entries.sort(key=lambda e: _sort_key(e[0]))
        for path in odd:
            report(
                str(path),
                f"the name does not follow {pattern}_depth.mat: left out unless asked for "
                f"by name ({_stem(path, 'depth')!r})",
            )
        depth_keys = {_stem(p, "depth").casefold() for p in depth_files}
        for path in skel_files:
            stem = _stem(path, "skeleton")
            if stem.casefold() in depth_keys:
                continue  # reported with its depth file, if at all
            if _NAME.match(path.name):
                report(str(path), f"no depth file {stem}_depth.mat in {str(depth_dir)!r}")
            else:
                report(str(path), f"the name does not follow {pattern}_skeleton.mat")
    else:
        if not depth_files:
            raise ValueError(
                f"The UTD-MHAD folder {str(root)!r} holds no '*_depth.mat' files "
                f"(looked in {str(depth_dir)!r})."
            )
        by_stem = {_stem(p, "depth"): p for p in depth_files}
        by_key: dict[str, list[Path]] = {}
        for path in depth_files:
            by_key.setdefault(_stem(path, "depth").casefold(), []).append(path)
        given: dict[str, bool] = {}  # name -> its repeat was reported
        chosen: dict[Path, str] = {}
        for name in names:
            if name in given:
                if not given[name]:  # said once, however often repeated
                    report(name, "named more than once: taken once")
                    given[name] = True
                continue
            given[name] = False
            path = by_stem.get(name)
            candidates = [path] if path is not None else by_key.get(name.casefold(), [])
            if len(candidates) > 1:
                listed = ", ".join(repr(p.name) for p in candidates)
                reason = f"several depth files match it in case ({listed}), none exactly"
                entries.append((name, None, None, reason))
                continue
            if not candidates:
                entries.append((name, None, None, "no such sequence in the folder"))
                continue
            (path,) = candidates
            if path in chosen:
                report(name, f"the same file as {chosen[path]!r} ({path.name}): taken once")
                continue
            chosen[path] = name
            entries.append(pair(path))
    if limit is not None:
        entries = entries[:limit]
    found = [(n, d, s) for n, d, s, why in entries if why is None]
    skipped = [(n, why) for n, _, _, why in entries if why is not None]
    return found, skipped
