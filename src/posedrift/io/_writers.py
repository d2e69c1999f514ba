"""Outputs of a tracked sequence: ``poses.json``, ``poses.csv``, ``poses.bvh``, point clouds."""

from __future__ import annotations

import csv
import json
import logging
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np

from posedrift.camera import Intrinsics
from posedrift.io._bvh_export import write_bvh
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES, PART_COLOURS, PART_NAMES
from posedrift.tracking import FrameResult

logger = logging.getLogger("posedrift.io")

CSV_COLUMNS: tuple[str, ...] = (
    ("index", "status", "timestamp", "bvh_pose")
    + tuple(f"{n}_{a}" for n in JOINT_NAMES for a in "xyz")
    + tuple(f"{n}_confidence" for n in JOINT_NAMES)
    + tuple(f"{n}_deg" for n in ANGLE_NAMES)
    + ("message",)
)
"""The columns of ``poses.csv``, in order."""


def _check_results(results: Sequence[FrameResult], caller: str) -> list[FrameResult]:
    results = list(results)
    for i, r in enumerate(results):
        if not isinstance(r, FrameResult):
            raise ValueError(
                f"The 'results' of {caller} must be FrameResult objects. "
                f"Item {i} is a {type(r).__name__}."
            )
    return results


def _sequence_fps(results: Sequence[FrameResult], fps: float | None) -> float:
    if fps is not None:
        if not (math.isfinite(fps) and fps > 0):
            raise ValueError(f"The 'fps' must be a positive frame rate. Got {fps!r} instead.")
        return float(fps)
    stamps = np.array([r.timestamp for r in results if r.timestamp is not None], dtype=float)
    steps = np.diff(stamps)
    steps = steps[steps > 0]
    if len(steps):
        return float(1.0 / np.median(steps))
    return 30.0


def _number(value: float | None) -> str:
    return "" if value is None or not math.isfinite(value) else repr(float(value))


def write_poses(
    results: Sequence[FrameResult],
    out_dir: str | Path,
    *,
    intrinsics: Intrinsics,
    fps: float | None = None,
    joint_convention: str = "native",
    smoothing: Mapping[str, float | None] | None = None,
) -> dict[str, Path]:
    """Write ``poses.json``, ``poses.csv`` and ``poses.bvh`` for a tracked sequence.

    Parameters
    ----------
    results : sequence of FrameResult
        One per frame, in order.
    out_dir : str or Path
        Created if needed.
    intrinsics : Intrinsics
        The camera of the sequence (written into ``poses.json``).
    fps : float, optional
        Frame rate of the BVH (and the JSON's ``fps``); by default from the
        results' timestamps, else 30.
    joint_convention : str
        The skeleton convention the results' joints are in, recorded in
        ``poses.json`` (``"native"``, or e.g. ``"kinect"`` after
        :func:`posedrift.skeleton.to_convention`); the joints are written as given.
    smoothing : mapping, optional
        How the results' joints were smoothed in time, recorded in ``poses.json``
        (``{"sigma_s": ..., "lag_s": ...}``, :func:`posedrift.tracking.smooth_results`);
        None (``null``): as tracked, frame by frame.

    Returns
    -------
    dict of str to Path
        ``{"json": ..., "csv": ..., "bvh": ...}``; ``"bvh"`` is absent when no frame
        has a complete pose (logged as a warning).

    Notes
    -----
    ``poses.json`` is the METHOD section 6 schema (``intrinsics``, ``joint_names``,
    ``angle_names``, ``frames`` with :meth:`FrameResult.to_json` objects) plus
    ``fps``, ``joint_convention``, ``smoothing`` and, per frame, ``bvh_pose``: ``"recovered"`` where
    the BVH frame holds this frame's pose, ``"held"`` where the frame had no complete
    pose and the BVH repeats the last known one. Joints are metres in the camera frame.

    Examples
    --------
    >>> import numpy as np, tempfile
    >>> from posedrift.camera import camera_preset
    >>> from posedrift.skeleton import t_pose_joints
    >>> from posedrift.tracking import FrameResult, FrameStatus
    >>> joints = t_pose_joints(1.75) * [1, -1, -1] + [0, 0.9, 2.8]
    >>> results = [FrameResult(i, FrameStatus.TRACKED, joints, np.ones(15)) for i in range(3)]
    >>> paths = write_poses(results, tempfile.mkdtemp(), intrinsics=camera_preset("kinect1-qvga"))
    >>> sorted(paths)
    ['bvh', 'csv', 'json']
    >>> read_poses(paths["csv"])[2]["angles_deg"]["left_shoulder"]
    90.0
    """
    results = _check_results(results, "write_poses")
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(
            "The 'intrinsics' of write_poses must be an Intrinsics. "
            f"Got {type(intrinsics).__name__}."
        )
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rate = _sequence_fps(results, fps)
    paths: dict[str, Path] = {}
    held = np.zeros(len(results), dtype=bool)
    bvh_ok = False
    if results:
        try:
            paths["bvh"], held = write_bvh(
                np.stack([r.joints for r in results]), out / "poses.bvh", fps=rate
            )
            bvh_ok = True
        except ValueError as exc:
            logger.warning("poses.bvh not written: %s", exc)
            (out / "poses.bvh").unlink(missing_ok=True)
    bvh_pose = [("held" if h else "recovered") if bvh_ok else "none" for h in held]

    frames = []
    for r, status in zip(results, bvh_pose, strict=True):
        frame = r.to_json()
        frame["confidence"] = [c if math.isfinite(c) else None for c in frame["confidence"]]
        if "timestamp" in frame and not math.isfinite(frame["timestamp"]):
            del frame["timestamp"]
        frame["bvh_pose"] = status
        frames.append(frame)
    document = {
        "intrinsics": intrinsics.to_dict(),
        "fps": rate,
        "joint_convention": joint_convention,
        "smoothing": None if smoothing is None else dict(smoothing),
        "joint_names": list(JOINT_NAMES),
        "angle_names": list(ANGLE_NAMES),
        "frames": frames,
    }
    paths["json"] = out / "poses.json"
    paths["json"].write_text(json.dumps(document, indent=1, allow_nan=False) + "\n")

    paths["csv"] = out / "poses.csv"
    with open(paths["csv"], "w", newline="") as fh:
        writer = csv.writer(fh)
        writer.writerow(CSV_COLUMNS)
        for r, status in zip(results, bvh_pose, strict=True):
            row = [str(int(r.index)), r.status.value, _number(r.timestamp), status]
            row += [_number(v) for v in r.joints.reshape(-1)]
            row += [_number(v) for v in r.confidence]
            row += [_number(v) for v in r.angles]
            row.append(r.message)
            writer.writerow(row)
    return {k: paths[k] for k in ("json", "csv", "bvh") if k in paths}


def _float_or_none(text: str) -> float | None:
    return float(text) if text != "" else None


def read_poses(path: str | Path) -> list[dict]:
    """Read back ``poses.json`` or ``poses.csv`` as a list of frame objects.

    Parameters
    ----------
    path : str or Path
        A ``.json`` or ``.csv`` file written by :func:`write_poses`, or the folder
        that holds ``poses.json``.

    Returns
    -------
    list of dict
        The ``frames`` of ``poses.json``: ``index``, ``status``, ``joints`` (15 x
        ``[x, y, z]`` or None), ``confidence``, ``angles_deg``, ``bvh_pose``, and
        ``timestamp`` / ``message`` where present.
    """
    path = Path(path)
    if path.is_dir():
        path = path / "poses.json"
    if not path.exists():
        raise FileNotFoundError(f"The poses file {str(path)!r} does not exist.")
    if path.suffix.lower() == ".json":
        try:
            document = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path} is not valid JSON: {exc}") from exc
        if "frames" not in document:
            raise ValueError(f"{path} has no 'frames' (keys found: {', '.join(document)}).")
        return document["frames"]
    if path.suffix.lower() != ".csv":
        raise ValueError(f"read_poses reads poses.json or poses.csv. Got {str(path)!r}.")
    frames = []
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        missing = [c for c in CSV_COLUMNS if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path} lacks the column(s) {missing[:5]}.")
        for row in reader:
            joints = []
            for n in JOINT_NAMES:
                xyz = [_float_or_none(row[f"{n}_{a}"]) for a in "xyz"]
                joints.append(None if any(v is None for v in xyz) else xyz)
            frame = {
                "index": int(row["index"]),
                "status": row["status"],
                "joints": joints,
                "confidence": [_float_or_none(row[f"{n}_confidence"]) for n in JOINT_NAMES],
                "angles_deg": {n: _float_or_none(row[f"{n}_deg"]) for n in ANGLE_NAMES},
                "bvh_pose": row["bvh_pose"],
            }
            if row["timestamp"] != "":
                frame["timestamp"] = float(row["timestamp"])
            if row["message"]:
                frame["message"] = row["message"]
            frames.append(frame)
    return frames


# ---------------------------------------------------------------------------------------------
# Point clouds


def _ply_bytes(points: np.ndarray, labels: np.ndarray) -> bytes:
    colours = np.array(PART_COLOURS + ((128, 128, 128),), dtype=np.uint8)
    safe = np.where((labels >= 0) & (labels < len(PART_NAMES)), labels, len(PART_NAMES))
    vertex = np.zeros(
        len(points),
        dtype=[
            ("x", "<f4"),
            ("y", "<f4"),
            ("z", "<f4"),
            ("red", "u1"),
            ("green", "u1"),
            ("blue", "u1"),
            ("label", "<i2"),
        ],
    )
    vertex["x"], vertex["y"], vertex["z"] = points.T
    vertex["red"], vertex["green"], vertex["blue"] = colours[safe].T
    vertex["label"] = labels
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        "comment posedrift labelled points: metres, camera frame (+X right, +Y down, +Z forward)\n"
        "comment label = part index (posedrift.skeleton.PART_NAMES), -1 unknown\n"
        f"element vertex {len(points)}\n"
        "property float x\nproperty float y\nproperty float z\n"
        "property uchar red\nproperty uchar green\nproperty uchar blue\n"
        "property short label\nend_header\n"
    )
    return header.encode("ascii") + vertex.tobytes()


def write_point_clouds(
    results: Sequence[FrameResult],
    out_dir: str | Path,
    *,
    fmt: str = "npz",
) -> list[Path]:
    """Write each frame's labelled points, one file per frame.

    Parameters
    ----------
    results : sequence of FrameResult
    out_dir : str or Path
        Files go to ``out_dir/NNNNNN.npz`` (keys ``points`` (N, 3) float32 metres,
        camera frame; ``labels`` (N,) int16 part index; ``index``) or ``.ply``
        (binary, with part colours and a ``label`` property).
    fmt : {"npz", "ply"}

    Returns
    -------
    list of Path
    """
    if fmt not in ("npz", "ply"):
        raise ValueError(f"The 'fmt' of write_point_clouds must be 'npz' or 'ply'. Got {fmt!r}.")
    results = _check_results(results, "write_point_clouds")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for r in results:
        points = np.asarray(r.points, dtype=np.float32).reshape(-1, 3)
        labels = np.asarray(r.labels, dtype=np.int16).reshape(-1)
        if len(labels) != len(points):
            labels = np.full(len(points), -1, dtype=np.int16)
        path = out / f"{int(r.index):06d}.{fmt}"
        if fmt == "npz":
            np.savez_compressed(path, points=points, labels=labels, index=np.int64(r.index))
        else:
            path.write_bytes(_ply_bytes(points, labels))
        paths.append(path)
    return paths


def read_point_cloud(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Read one file written by :func:`write_point_clouds`: ``(points (N, 3), labels (N,))``."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path) as data:
            return data["points"], data["labels"]
    data = path.read_bytes()
    end = data.index(b"end_header\n") + len(b"end_header\n")
    header = data[:end].decode("ascii").splitlines()
    count = next(int(line.split()[-1]) for line in header if line.startswith("element vertex"))
    dtype = [
        ("x", "<f4"),
        ("y", "<f4"),
        ("z", "<f4"),
        ("red", "u1"),
        ("green", "u1"),
        ("blue", "u1"),
        ("label", "<i2"),
    ]
    vertex = np.frombuffer(data, dtype=dtype, count=count, offset=end)
    return np.column_stack([vertex["x"], vertex["y"], vertex["z"]]), vertex["label"].copy()
