"""The synthetic folder format of ``posedrift synth`` (``METHOD.md`` section 6).

::

    DIR/depth/NNNNNN.png     uint16 millimetres, 0 = no measurement
    DIR/labels/NNNNNN.png    uint8 part index + 1, 0 = background
    DIR/ground_truth.json    {"intrinsics": {fx, fy, cx, cy, width, height}, "fps": x,
                              "joint_names": [15], "angle_names": [8], "name": str,
                              "frames": [{"index": i, "joints": [[x, y, z] x 15],
                                          "angles_deg": {"left_elbow": x, ...}}]}

Joints are in metres in the camera frame (+X right, +Y down, +Z forward); NaN is
written as null. ``name`` is an extension of the documented schema.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.evaluation._types import EvaluationSequence, Reference
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, PART_COLOURS, angles_dict
from posedrift.synthetic._render import depth_to_mm

GROUND_TRUTH = "ground_truth.json"
DEPTH_DIR = "depth"
LABELS_DIR = "labels"


def _frame_file(index: int) -> str:
    return f"{index:06d}.png"


def write_synthetic(
    sequence: EvaluationSequence,
    out_dir: str | os.PathLike,
    *,
    progress: bool = False,
) -> dict[str, Path]:
    """Write a sequence as a synthetic folder (depth PNG16, label PNG, ground truth JSON).

    Parameters
    ----------
    sequence : EvaluationSequence
        Its reference must hold joints; labels are written where it has them.
    out_dir : path
        Created if missing; existing frame files are overwritten and frame files
        beyond this sequence's length (``NNNNNN.png`` from an earlier run) removed.
    progress : bool
        Draw a progress bar (rich) on standard error.

    Returns
    -------
    dict
        ``{"depth": DIR/depth, "labels": DIR/labels, "ground_truth": DIR/ground_truth.json}``
        (``labels`` only where written).
    """
    import imageio.v3 as iio

    if not isinstance(sequence, EvaluationSequence):
        raise ValueError(
            f"The 'sequence' argument of write_synthetic must be an EvaluationSequence. "
            f"Got {type(sequence).__name__} instead."
        )
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"The output folder {str(out)!r} exists and is not a folder.")
    depth_dir = out / DEPTH_DIR
    depth_dir.mkdir(parents=True, exist_ok=True)
    ref = sequence.reference
    labels = ref.labels
    paths = {"depth": depth_dir}
    if labels is not None:
        label_dir = out / LABELS_DIR
        label_dir.mkdir(exist_ok=True)
        paths["labels"] = label_dir
    # Frames of an earlier, longer sequence in the same folder would be read as ours.
    keep = {_frame_file(i) for i in range(len(sequence.frames))}
    for folder in (depth_dir, out / LABELS_DIR):
        if folder.is_dir():
            for stale in folder.glob("[0-9][0-9][0-9][0-9][0-9][0-9].png"):
                if stale.name not in keep:
                    stale.unlink()
    intrinsics = sequence.frames[0].intrinsics if sequence.frames else None
    frames_json = []
    with _progress_bar(progress, len(sequence.frames), f"writing {out}") as advance:
        for i, frame in enumerate(sequence.frames):
            name = _frame_file(i)
            iio.imwrite(depth_dir / name, depth_to_mm(frame.depth))
            if labels is not None:
                iio.imwrite(out / LABELS_DIR / name, np.asarray(labels[i], dtype=np.uint8))
            joints = [
                [None if not np.isfinite(c) else float(c) for c in joint] for joint in ref.joints[i]
            ]
            frames_json.append(
                {"index": i, "joints": joints, "angles_deg": angles_dict(ref.angles[i])}
            )
            advance()
    truth = {
        "intrinsics": intrinsics.to_dict() if intrinsics is not None else None,
        "fps": float(sequence.fps),
        "joint_names": list(JOINT_NAMES),
        "angle_names": list(ANGLE_NAMES),
        "name": sequence.name,
        "frames": frames_json,
    }
    path = out / GROUND_TRUTH
    path.write_text(json.dumps(truth, indent=1) + "\n")
    paths["ground_truth"] = path
    return paths


def read_synthetic(directory: str | os.PathLike) -> EvaluationSequence:
    """Read a folder written by :func:`write_synthetic` (or ``posedrift synth``).

    Parameters
    ----------
    directory : path
        Holds ``ground_truth.json``, ``depth/`` and (optionally) ``labels/``.

    Returns
    -------
    EvaluationSequence
        Depth frames in metres (from millimetres), the reference joints (camera
        frame, metres), angles (degrees) and labels (None without ``labels/``).

    Raises
    ------
    ValueError
        Naming the file: a missing or malformed ``ground_truth.json``, a missing,
        unreadable or wrongly shaped or typed PNG, or label values above 15.
    """
    import imageio.v3 as iio

    root = Path(directory)
    gt_path = root / GROUND_TRUTH
    if not root.is_dir():
        raise ValueError(f"Synthetic folder {str(root)!r} does not exist or is not a folder.")
    if not gt_path.is_file():
        raise ValueError(f"Synthetic folder {str(root)!r} has no {GROUND_TRUTH}.")
    try:
        truth = json.loads(gt_path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise ValueError(f"{gt_path}: not readable JSON ({exc}).") from exc
    if not isinstance(truth, dict):
        raise ValueError(f"{gt_path}: expected a JSON object at the top level.")
    missing = [
        k for k in ("intrinsics", "fps", "joint_names", "angle_names", "frames") if k not in truth
    ]
    if missing:
        raise ValueError(f"{gt_path}: missing key(s) {missing}.")
    try:
        intrinsics = Intrinsics.from_dict(truth["intrinsics"])
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{gt_path}: bad 'intrinsics': {exc}") from exc
    if list(truth["joint_names"]) != list(JOINT_NAMES):
        raise ValueError(f"{gt_path}: 'joint_names' must be {list(JOINT_NAMES)}.")
    if list(truth["angle_names"]) != list(ANGLE_NAMES):
        raise ValueError(f"{gt_path}: 'angle_names' must be {list(ANGLE_NAMES)}.")
    fps = truth["fps"]
    if not isinstance(fps, int | float) or not fps > 0:
        raise ValueError(f"{gt_path}: 'fps' must be a positive number. Got {fps!r}.")
    records = truth["frames"]
    if not isinstance(records, list) or not records:
        raise ValueError(f"{gt_path}: 'frames' must be a non-empty list.")
    name = str(truth.get("name") or root.name)
    label_dir = root / LABELS_DIR
    has_labels = label_dir.is_dir()

    joints = np.empty((len(records), len(JOINT_NAMES), 3))
    angles = np.empty((len(records), len(ANGLE_NAMES)))
    frames: list[DepthFrame] = []
    labels: list[np.ndarray] = []
    for t, rec in enumerate(records):
        where = f"{gt_path}, frames[{t}]"
        try:
            index = int(rec["index"])
            joints[t] = np.array(
                [[np.nan if c is None else float(c) for c in j] for j in rec["joints"]]
            )
            angles[t] = [
                np.nan if rec["angles_deg"][a] is None else float(rec["angles_deg"][a])
                for a in ANGLE_NAMES
            ]
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{where}: malformed frame record ({exc!r}).") from exc
        depth_path = root / DEPTH_DIR / _frame_file(index)
        raw = _read_png(iio, depth_path, np.uint16, intrinsics.shape)
        frames.append(
            DepthFrame.from_raw(
                raw, intrinsics, depth_scale=1000.0, index=t, timestamp=t / fps, source=name
            )
        )
        if has_labels:
            label_path = label_dir / _frame_file(index)
            label = _read_png(iio, label_path, np.uint8, intrinsics.shape)
            if label.max(initial=0) > len(JOINT_NAMES):
                raise ValueError(
                    f"{label_path}: label values must be 0 (background) to 15 (part + 1). "
                    f"Got {int(label.max())}."
                )
            label.setflags(write=False)
            labels.append(label)
    reference = Reference(
        joints=joints, angles=angles, labels=tuple(labels) if has_labels else None
    )
    return EvaluationSequence(name=name, frames=tuple(frames), reference=reference, fps=float(fps))


def _read_png(iio, path: Path, dtype: type, shape: tuple[int, int]) -> np.ndarray:
    if not path.is_file():
        raise ValueError(f"{path}: missing frame file.")
    try:
        image = iio.imread(path)
    except Exception as exc:  # imageio raises many types for a bad file
        raise ValueError(f"{path}: not a readable PNG ({exc}).") from exc
    if image.dtype != dtype or image.shape != shape:
        raise ValueError(
            f"{path}: expected a {np.dtype(dtype).name} image of shape {shape}. "
            f"Got {image.dtype} {image.shape}."
        )
    return image


class _progress_bar:
    """A rich progress bar on standard error, or nothing."""

    def __init__(self, enabled: bool, total: int, description: str) -> None:
        self.enabled = enabled
        self.total = total
        self.description = description
        self._progress = None
        self._task = None

    def __enter__(self):
        if not self.enabled:
            return lambda: None
        from rich.console import Console
        from rich.progress import Progress

        self._progress = Progress(console=Console(stderr=True), transient=True)
        self._progress.start()
        self._task = self._progress.add_task(self.description, total=self.total)
        return lambda: self._progress.advance(self._task)

    def __exit__(self, *exc) -> None:
        if self._progress is not None:
            self._progress.stop()


def colour_labels(labels: np.ndarray) -> np.ndarray:
    """``(H, W)`` part labels (part + 1, 0 background) to ``(H, W, 3)`` uint8 RGB.

    Background is black; each part takes its :data:`PART_COLOURS` colour.

    Examples
    --------
    >>> import numpy as np
    >>> colour_labels(np.array([[0, 1]], dtype=np.uint8)).tolist()
    [[[0, 0, 0], [230, 25, 75]]]
    """
    lut = np.zeros((256, 3), dtype=np.uint8)
    lut[1 : len(PART_COLOURS) + 1] = PART_COLOURS
    return lut[np.asarray(labels, dtype=np.uint8)]


def colour_depth(depth: np.ndarray, *, near: float | None = None, far: float | None = None):
    """``(H, W)`` depth in metres to ``(H, W, 3)`` uint8 RGB (turbo colour map), empty black.

    ``near`` / ``far`` default to the 1st and 99th percentiles of the valid depth.
    """
    from matplotlib import colormaps

    depth = np.asarray(depth, dtype=float)
    valid = np.isfinite(depth) & (depth > 0)
    rgb = np.zeros(depth.shape + (3,), dtype=np.uint8)
    if not valid.any():
        return rgb
    lo = float(np.percentile(depth[valid], 1)) if near is None else near
    hi = float(np.percentile(depth[valid], 99)) if far is None else far
    scaled = np.clip((depth[valid] - lo) / max(hi - lo, 1e-6), 0.0, 1.0)
    rgb[valid] = (colormaps["turbo"](1.0 - scaled)[:, :3] * 255).astype(np.uint8)
    return rgb


def contact_sheet(
    sequence: EvaluationSequence,
    path: str | os.PathLike,
    *,
    frames: Sequence[int] | int = 6,
    columns: int = 2,
    scale: int = 1,
) -> Path:
    """A PNG for a person to look at: depth (colour-mapped) beside labels, a few frames.

    Each tile is one frame: depth (turbo colour map over the person's depth range and
    half a metre behind, near is red, empty black) on the left, the part labels
    (:data:`PART_COLOURS`, background black) on the right. Tiles run left to right,
    then down, separated by grey bands.

    Parameters
    ----------
    sequence : EvaluationSequence
        Labels come from its reference (black where it has none).
    path : path
        The PNG to write.
    frames : int or sequence of int
        Frame indices, or how many evenly spaced frames (the first and the last frame
        that show the person included; all frames when none does).
    columns : int
        Tiles per row.
    scale : int
        Integer upscaling of every pixel.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        For an empty sequence or a frame index outside it.
    """
    import imageio.v3 as iio

    n = len(sequence.frames)
    if n == 0:
        raise ValueError("contact_sheet needs a sequence with at least one frame.")
    labels = sequence.reference.labels
    if isinstance(frames, int):
        shown = np.arange(n)
        if labels is not None:
            visible = np.flatnonzero([np.any(lab) for lab in labels])
            shown = visible if len(visible) else shown
        pick = np.linspace(0, len(shown) - 1, min(max(frames, 1), len(shown))).round()
        picks = np.unique(shown[pick.astype(int)]).tolist()
    else:
        picks = [int(i) for i in frames]
        bad = [i for i in picks if not 0 <= i < n]
        if bad or not picks:
            raise ValueError(f"contact_sheet: frame(s) {bad} outside the sequence's 0..{n - 1}.")
    # Colour range: the person's depth (and half a metre behind) where labels say where
    # the person is, so that the body's relief shows; else all valid depth.
    person = [
        np.asarray(sequence.frames[i].depth)[labels[i] > 0] if labels is not None else []
        for i in picks
    ]
    values = np.concatenate([np.ravel(p) for p in person])
    values = values[values > 0]
    if len(values):
        near, far = float(values.min()) - 0.05, float(values.max()) + 0.5
    else:
        near = far = None
    grey = 128
    tiles = []
    for i in picks:
        depth = sequence.frames[i].depth
        lab = labels[i] if labels is not None else np.zeros(depth.shape, np.uint8)
        gap = np.full((depth.shape[0], 2, 3), grey, dtype=np.uint8)
        tiles.append(
            np.concatenate([colour_depth(depth, near=near, far=far), gap, colour_labels(lab)], 1)
        )
    columns = max(1, min(int(columns), len(tiles)))
    blank = np.full_like(tiles[0], grey)
    tiles += [blank] * (-len(tiles) % columns)
    h, w = tiles[0].shape[:2]
    band = 6
    rows_n = len(tiles) // columns
    sheet = np.full(
        (rows_n * h + (rows_n - 1) * band, columns * w + (columns - 1) * band, 3),
        grey,
        dtype=np.uint8,
    )
    for k, tile in enumerate(tiles):
        r, c = divmod(k, columns)
        sheet[r * (h + band) : r * (h + band) + h, c * (w + band) : c * (w + band) + w] = tile
    if scale > 1:
        sheet = np.repeat(np.repeat(sheet, scale, axis=0), scale, axis=1)
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(out, sheet)
    return out
