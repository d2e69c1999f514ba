"""Depth inputs behind one reader interface: PNG folders, NumPy stacks, UTD-MHAD ``.mat``.

Every source yields :class:`~posedrift.camera.DepthFrame` objects (depth in metres,
camera intrinsics, index, timestamp in seconds, source name) in order, or an
:class:`UnreadableFrame` where one frame cannot be read, and then goes on.
"""

from __future__ import annotations

import logging
import re
import struct
import zipfile
from collections import Counter
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posedrift.camera import CAMERA_PRESETS, DepthFrame, Intrinsics, camera_preset
from posedrift.camera import parse_intrinsics as _parse_intrinsics

logger = logging.getLogger("posedrift.io")

DEFAULT_FPS = 30.0
"""Frame rate assumed for timestamps when a source gives none."""

DEFAULT_DEPTH_SCALE = 1000.0
"""Depth units per metre assumed for integer depth (millimetres)."""

DEPTH_SCALES = {"mm": 1000.0, "tum": 5000.0, "m": 1.0}
"""Named depth scales (units per metre) accepted where a number is expected."""

_SIZE_PRESETS = {
    (240, 320): "kinect1-qvga",
    (480, 640): "kinect1-vga",
    (424, 512): "kinect2",
}
"""Image shape (height, width) -> the preset assumed when no camera is given."""

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_NPZ_DEPTH_KEYS = ("depth", "d_depth", "frames")


@dataclass(frozen=True)
class UnreadableFrame:
    """A frame that could not be read; a source yields it in place of the frame and goes on.

    Parameters
    ----------
    index : int
        The frame's position in its sequence.
    source : str
        The file (or file and record) it came from.
    message : str
        Why it could not be read.
    """

    index: int
    source: str
    message: str

    def __str__(self) -> str:
        return f"frame {self.index} ({self.source}): {self.message}"


def resolve_depth_scale(depth_scale: float | str | None, *, default: float) -> float:
    """Depth units per metre from a number, a name in :data:`DEPTH_SCALES`, or None.

    Examples
    --------
    >>> resolve_depth_scale("tum", default=1000.0)
    5000.0
    >>> resolve_depth_scale(None, default=1000.0)
    1000.0
    """
    if depth_scale is None:
        return float(default)
    if isinstance(depth_scale, str):
        key = depth_scale.strip().lower()
        if key in DEPTH_SCALES:
            return DEPTH_SCALES[key]
        try:
            depth_scale = float(key)
        except ValueError:
            raise ValueError(
                f"The 'depth_scale' option must be depth units per metre (a positive number) "
                f"or one of {', '.join(DEPTH_SCALES)}. Got {depth_scale!r} instead."
            ) from None
    value = float(depth_scale)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(
            f"The 'depth_scale' option must be depth units per metre (a positive number: "
            f"1000 for millimetres, 5000 for TUM). Got {depth_scale!r} instead."
        )
    return value


def resolve_intrinsics(
    shape: tuple[int, int],
    *,
    camera: str | None = None,
    intrinsics: Intrinsics | str | Sequence[float] | None = None,
    where: str = "the input",
) -> Intrinsics:
    """The intrinsics for images of ``shape`` from a preset name, explicit values, or the size.

    Parameters
    ----------
    shape : (int, int)
        Image ``(height, width)``.
    camera : str, optional
        A name in :data:`posedrift.camera.CAMERA_PRESETS`.
    intrinsics : Intrinsics, str ``"fx,fy,cx,cy"`` or 4 numbers, optional
        Explicit values; a string or sequence takes the image size from ``shape``.
    where : str
        The input's name, for messages.

    Raises
    ------
    ValueError
        If both are given, the preset is unknown, the size disagrees with the image, or
        neither is given and the size matches no preset.
    """
    height, width = (int(shape[0]), int(shape[1]))
    if camera is not None and intrinsics is not None:
        raise ValueError("Give either a camera preset or explicit intrinsics, not both.")
    if camera is not None:
        result = camera_preset(camera)
        if result.shape != (height, width):
            raise ValueError(
                f"The camera preset {camera!r} is {result.width} x {result.height} pixels but "
                f"{where} has {width} x {height} frames. Presets by size: "
                + ", ".join(f"{n} ({p.width}x{p.height})" for n, p in CAMERA_PRESETS.items())
                + "; or give --intrinsics fx,fy,cx,cy."
            )
        return result
    if intrinsics is not None:
        if isinstance(intrinsics, Intrinsics):
            result = intrinsics
        elif isinstance(intrinsics, str):
            result = _parse_intrinsics(intrinsics, width=width, height=height)
        else:
            values = [float(v) for v in intrinsics]
            if len(values) != 4:
                raise ValueError(
                    f"The 'intrinsics' must be four numbers (fx, fy, cx, cy). Got {values}."
                )
            fx, fy, cx, cy = values
            result = Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height)
        if result.shape != (height, width):
            raise ValueError(
                f"The intrinsics are for {result.width} x {result.height} images but {where} has "
                f"{width} x {height} frames."
            )
        return result
    name = _SIZE_PRESETS.get((height, width))
    if name is None:
        raise ValueError(
            f"No camera is known for {width} x {height} depth frames ({where}). Give "
            f"--camera NAME (one of {', '.join(CAMERA_PRESETS)}) or --intrinsics fx,fy,cx,cy."
        )
    logger.info(
        "No camera given: assuming the %r preset for %d x %d frames (%s).",
        name,
        width,
        height,
        where,
    )
    return CAMERA_PRESETS[name]


class DepthSource:
    """A sequence of depth frames from one input, read lazily and in order.

    Iterating yields :class:`~posedrift.camera.DepthFrame` or, for a frame that
    cannot be read, :class:`UnreadableFrame`; the iteration goes on after it.

    Attributes
    ----------
    path : Path
        The input.
    intrinsics : Intrinsics
        The camera of every frame.
    depth_scale : float
        Depth units per metre of the raw data.
    fps : float
        Frame rate used for timestamps where the input has none.
    unmirror : bool
        Whether frames are flipped left-right (mirrored recordings such as
        UTD-MHAD); ``intrinsics`` then describe the flipped image.
    """

    path: Path
    intrinsics: Intrinsics
    depth_scale: float
    fps: float
    unmirror: bool = False

    def __len__(self) -> int:
        raise NotImplementedError

    def _set_unmirror(self, unmirror: bool) -> None:
        """Flip frames left-right (for mirrored recordings) and adjust ``cx`` to match."""
        self.unmirror = bool(unmirror)
        if self.unmirror:
            k = self.intrinsics
            self.intrinsics = Intrinsics(
                fx=k.fx, fy=k.fy, cx=(k.width - 1) - k.cx, cy=k.cy, width=k.width, height=k.height
            )

    def _frame(self, raw: np.ndarray, *, index: int, timestamp: float, source: str) -> DepthFrame:
        if self.unmirror:
            raw = np.ascontiguousarray(np.asarray(raw)[:, ::-1])
        return DepthFrame.from_raw(
            raw,
            self.intrinsics,
            depth_scale=self.depth_scale,
            index=index,
            timestamp=timestamp,
            source=source,
        )

    def __iter__(self) -> Iterator[DepthFrame | UnreadableFrame]:
        raise NotImplementedError

    def __repr__(self) -> str:
        return (
            f"{type(self).__name__}({str(self.path)!r}, frames={len(self)}, "
            f"{self.intrinsics.width}x{self.intrinsics.height}, depth_scale={self.depth_scale:g})"
        )


# ---------------------------------------------------------------------------------------------
# PNG folders


def _png_header(path: Path) -> tuple[int, int, int, int]:
    """``(width, height, bit_depth, colour_type)`` from a PNG's IHDR chunk."""
    with open(path, "rb") as fh:
        head = fh.read(33)
    if len(head) < 33 or head[:8] != _PNG_SIGNATURE or head[12:16] != b"IHDR":
        raise ValueError("not a PNG file (bad signature or header)")
    width, height, bit_depth, colour_type = struct.unpack(">IIBB", head[16:26])
    return width, height, bit_depth, colour_type


_COLOUR_TYPES = {0: "greyscale", 2: "RGB", 3: "palette", 4: "greyscale+alpha", 6: "RGBA"}


def _natural_key(path: Path) -> tuple:
    return tuple(int(t) if t.isdigit() else t for t in re.split(r"(\d+)", path.name))


_DEPTH_SUBFOLDER = "depth"
_SYNTH_GROUND_TRUTH = "ground_truth.json"


def _png_files(folder: Path) -> list[Path]:
    """The ``.png`` files directly in ``folder``, in natural name order."""
    return sorted((p for p in folder.iterdir() if p.suffix.lower() == ".png"), key=_natural_key)


def _synthetic_folder_info(folder: Path) -> dict:
    """The camera and frame rate a ``posedrift synth`` folder records, if it is one.

    Returns ``{"where": path, "intrinsics": Intrinsics, "fps": float}`` (the keys
    that could be read) for a folder with ``depth/`` and ``ground_truth.json``,
    else ``{}``. A malformed file is only logged: the frames can still be read.
    """
    import json

    truth_path = folder / _SYNTH_GROUND_TRUTH
    if not ((folder / _DEPTH_SUBFOLDER).is_dir() and truth_path.is_file()):
        return {}
    info: dict = {"where": str(truth_path)}
    try:
        truth = json.loads(truth_path.read_text())
        if truth.get("intrinsics") is not None:
            info["intrinsics"] = Intrinsics.from_dict(truth["intrinsics"])
        fps = truth.get("fps")
        if isinstance(fps, int | float) and np.isfinite(fps) and fps > 0:
            info["fps"] = float(fps)
    except (OSError, UnicodeDecodeError, ValueError, TypeError, KeyError, AttributeError) as exc:
        logger.warning("Ignoring %s (%s); reading the depth frames alone.", truth_path, exc)
    return info


class PngFolderSource(DepthSource):
    """A folder of 16-bit greyscale PNG depth frames, in natural file-name order.

    Frame timestamps come from file names that are times in seconds (TUM RGB-D's
    ``1305031102.160407.png``), else ``index / fps``.

    A folder with a ``depth/`` subfolder of PNGs (as ``posedrift synth`` and TUM
    RGB-D write) reads the frames there; anything beside them (a contact sheet,
    ``rgb/``) is ignored. A ``posedrift synth`` folder's ``ground_truth.json``
    gives the intrinsics (unless ``camera`` or ``intrinsics`` is given) and the
    frame rate.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        camera: str | None = None,
        intrinsics: Intrinsics | str | Sequence[float] | None = None,
        depth_scale: float | str | None = None,
        fps: float = DEFAULT_FPS,
        unmirror: bool = False,
    ) -> None:
        folder = Path(path)
        synth = _synthetic_folder_info(folder)
        if (folder / _DEPTH_SUBFOLDER).is_dir() and _png_files(folder / _DEPTH_SUBFOLDER):
            # a folder of `posedrift synth` (or a TUM sequence): the frames are in depth/,
            # whatever else (contact_sheet.png, rgb/) lies beside them
            folder = folder / _DEPTH_SUBFOLDER
        files = _png_files(folder)
        if not files:
            raise ValueError(
                f"The folder {str(path)!r} holds no .png depth frames (nor does a 'depth' "
                f"subfolder). Expected 16-bit greyscale PNG files such as 000000.png."
            )
        if synth and camera is None and intrinsics is None and "intrinsics" in synth:
            intrinsics = synth["intrinsics"]
            logger.info("Using the intrinsics of %s.", synth["where"])
        if synth and "fps" in synth:
            fps = synth["fps"]
        self.path = folder
        self.files = tuple(files)
        self.fps = float(fps)
        self.depth_scale = resolve_depth_scale(depth_scale, default=DEFAULT_DEPTH_SCALE)
        headers: dict[int, tuple[int, int, int, int]] = {}
        for i, file in enumerate(files):
            try:
                headers[i] = _png_header(file)
            except (OSError, ValueError):
                continue  # reported as an UnreadableFrame when iterated
        good = {i: h for i, h in headers.items() if h[2] == 16 and h[3] == 0}
        if not good:
            if headers:
                i, (_w, _h, bits, ctype) = next(iter(headers.items()))
                raise ValueError(
                    f"{files[i]} is a {bits}-bit {_COLOUR_TYPES.get(ctype, 'unknown')} PNG; "
                    f"depth frames must be 16-bit greyscale PNG (uint16 depth units, "
                    f"--depth-scale units per metre). No frame in {str(folder)!r} is."
                )
            raise ValueError(f"None of the {len(files)} PNG files in {str(folder)!r} is readable.")
        sizes = Counter((h[1], h[0]) for h in good.values())
        self._shape = sizes.most_common(1)[0][0]
        if len(sizes) > 1:
            odd = [files[i].name for i, h in good.items() if (h[1], h[0]) != self._shape]
            logger.warning(
                "%d frame(s) in %s differ from the common size %d x %d and will be skipped: %s",
                len(odd),
                folder,
                self._shape[1],
                self._shape[0],
                ", ".join(odd[:5]) + (" ..." if len(odd) > 5 else ""),
            )
        self._headers = headers
        self.intrinsics = resolve_intrinsics(
            self._shape, camera=camera, intrinsics=intrinsics, where=str(folder)
        )
        self._set_unmirror(unmirror)
        self._timestamps = self._name_timestamps()

    def _name_timestamps(self) -> np.ndarray | None:
        try:
            stamps = [float(p.stem) for p in self.files]
        except ValueError:
            return None
        if not all("." in p.stem for p in self.files):
            return None
        stamps = np.asarray(stamps)
        return stamps - stamps[0]

    def __len__(self) -> int:
        return len(self.files)

    def _read(self, index: int) -> np.ndarray:
        from PIL import Image

        file = self.files[index]
        header = self._headers.get(index)
        if header is None:
            _png_header(file)  # raises with the reason
        width, height, bits, ctype = header
        if bits != 16 or ctype != 0:
            raise ValueError(
                f"a {bits}-bit {_COLOUR_TYPES.get(ctype, 'unknown')} PNG; depth frames must be "
                f"16-bit greyscale"
            )
        if (height, width) != self._shape:
            raise ValueError(
                f"its size {width} x {height} differs from the sequence's "
                f"{self._shape[1]} x {self._shape[0]}"
            )
        with Image.open(file) as image:
            image.load()
            raw = np.array(image)
        if raw.shape != self._shape:
            raise ValueError(f"decoded to shape {raw.shape}, expected {self._shape}")
        return raw.astype(np.uint16, copy=False)

    def __iter__(self) -> Iterator[DepthFrame | UnreadableFrame]:
        for i, file in enumerate(self.files):
            try:
                raw = self._read(i)
            except Exception as exc:
                yield UnreadableFrame(i, str(file), f"cannot read this PNG: {exc}")
                continue
            stamp = float(self._timestamps[i]) if self._timestamps is not None else i / self.fps
            yield self._frame(raw, index=i, timestamp=stamp, source=str(file))


# ---------------------------------------------------------------------------------------------
# Array stacks: .npy, .npz, UTD-MHAD .mat


class ArraySource(DepthSource):
    """A stack of depth frames held in an array ``(T, H, W)``.

    Integer depth is read in ``depth_scale`` units per metre (millimetres by
    default); floating-point depth in metres unless ``depth_scale`` is given.
    """

    def __init__(
        self,
        path: str | Path,
        stack: np.ndarray,
        *,
        camera: str | None = None,
        intrinsics: Intrinsics | str | Sequence[float] | None = None,
        depth_scale: float | str | None = None,
        fps: float = DEFAULT_FPS,
        timestamps: np.ndarray | None = None,
        record: str = "",
        unmirror: bool = False,
    ) -> None:
        self.path = Path(path)
        stack = np.asarray(stack) if not isinstance(stack, np.memmap) else stack
        if stack.ndim == 2:
            stack = stack[None]
        if stack.ndim != 3:
            raise ValueError(
                f"{self.path}{record}: a depth stack must have shape (frames, height, width). "
                f"Got shape {stack.shape}."
            )
        if not (np.issubdtype(stack.dtype, np.integer) or np.issubdtype(stack.dtype, np.floating)):
            raise ValueError(
                f"{self.path}{record}: depth must be integer or floating-point numbers. "
                f"Got dtype {stack.dtype}."
            )
        if len(stack) == 0:
            raise ValueError(f"{self.path}{record}: the depth stack holds no frames.")
        self.stack = stack
        self.record = record
        self.fps = float(fps)
        default = DEFAULT_DEPTH_SCALE if np.issubdtype(stack.dtype, np.integer) else 1.0
        self.depth_scale = resolve_depth_scale(depth_scale, default=default)
        self.intrinsics = resolve_intrinsics(
            stack.shape[1:], camera=camera, intrinsics=intrinsics, where=str(self.path)
        )
        self._set_unmirror(unmirror)
        if timestamps is not None:
            timestamps = np.asarray(timestamps, dtype=float).reshape(-1)
            if len(timestamps) != len(stack):
                raise ValueError(
                    f"{self.path}: 'timestamps' has {len(timestamps)} values for "
                    f"{len(stack)} frames."
                )
        self.timestamps = timestamps

    def __len__(self) -> int:
        return len(self.stack)

    def __iter__(self) -> Iterator[DepthFrame | UnreadableFrame]:
        for i in range(len(self.stack)):
            source = f"{self.path}{self.record}[{i}]"
            try:
                raw = np.asarray(self.stack[i])
            except Exception as exc:
                yield UnreadableFrame(i, source, str(exc))
                continue
            stamp = float(self.timestamps[i]) if self.timestamps is not None else i / self.fps
            yield self._frame(raw, index=i, timestamp=stamp, source=source)


def _open_npy(path: Path, **options) -> ArraySource:
    try:
        stack = np.load(path, mmap_mode="r", allow_pickle=False)
    except Exception as exc:
        raise ValueError(f"Cannot read the NumPy file {str(path)!r}: {exc}") from exc
    return ArraySource(path, stack, **options)


def _open_npz(path: Path, **options) -> ArraySource:
    try:
        archive = np.load(path, allow_pickle=False)
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise ValueError(f"Cannot read the NumPy archive {str(path)!r}: {exc}") from exc
    with archive:
        keys = list(archive.files)
        key = next((k for k in _NPZ_DEPTH_KEYS if k in keys), None)
        if key is None and len(keys) == 1:
            key = keys[0]
        if key is None:
            raise ValueError(
                f"The archive {str(path)!r} has no depth array: expected a key named "
                f"{' or '.join(repr(k) for k in _NPZ_DEPTH_KEYS)} (or a single array). "
                f"Keys found: {', '.join(keys) if keys else 'none'}."
            )
        stack = archive[key]
        if "intrinsics" in keys and options.get("camera") is None:
            if options.get("intrinsics") is None:
                values = np.asarray(archive["intrinsics"], dtype=float).reshape(-1)
                if values.shape != (4,):
                    raise ValueError(
                        f"{path}: the 'intrinsics' array must hold fx, fy, cx, cy. "
                        f"Got shape {values.shape}."
                    )
                options["intrinsics"] = [float(v) for v in values]
        if "timestamps" in keys:
            options["timestamps"] = np.asarray(archive["timestamps"], dtype=float)
        if "depth_scale" in keys and options.get("depth_scale") is None:
            options["depth_scale"] = float(archive["depth_scale"])
    return ArraySource(path, stack, record=f":{key}", **options)


def _open_mat(path: Path, **options) -> ArraySource:
    from scipy.io import loadmat, whosmat

    try:
        names = [name for name, _, _ in whosmat(path)]
    except NotImplementedError as exc:
        raise ValueError(
            f"{path} is a MATLAB v7.3 (HDF5) file, which is not supported; save it with "
            f"-v7 or convert it to .npy."
        ) from exc
    except Exception as exc:
        raise ValueError(f"Cannot read the MATLAB file {str(path)!r}: {exc}") from exc
    key = "d_depth" if "d_depth" in names else ("depth" if "depth" in names else None)
    if key is None:
        raise ValueError(
            f"The MATLAB file {str(path)!r} has no depth variable: expected 'd_depth' "
            f"(UTD-MHAD) or 'depth'. Variables found: {', '.join(names) if names else 'none'}."
        )
    try:
        data = loadmat(path, variable_names=[key])[key]
    except Exception as exc:  # scipy says only "could not read bytes" for a truncated file
        raise ValueError(
            f"Cannot read the variable {key!r} of the MATLAB file {str(path)!r} "
            f"(truncated or corrupt?): {exc}"
        ) from exc
    if data.ndim == 3:
        data = np.moveaxis(data, -1, 0)  # UTD-MHAD stores height x width x frames
    if options.get("unmirror") is None:
        # UTD-MHAD's depth images are mirrored (the person's left arm on the image's left)
        options["unmirror"] = key == "d_depth"
    return ArraySource(path, data, record=f":{key}", **options)


# ---------------------------------------------------------------------------------------------


def open_depth_source(
    path: str | Path,
    *,
    camera: str | None = None,
    intrinsics: Intrinsics | str | Sequence[float] | None = None,
    depth_scale: float | str | None = None,
    fps: float = DEFAULT_FPS,
    unmirror: bool | None = None,
) -> DepthSource:
    """Open a depth recording, choosing the reader by its suffix (or a folder).

    Parameters
    ----------
    path : str or Path
        A folder of 16-bit PNG frames (or a folder with a ``depth/`` subfolder, as
        ``posedrift synth`` writes), an ``.npy`` stack ``(T, H, W)``, an ``.npz``
        archive (key ``depth`` or a single array; optional ``intrinsics`` fx, fy,
        cx, cy, ``timestamps`` in seconds and ``depth_scale``), a UTD-MHAD ``.mat``
        file (``d_depth``, H x W x T), or an Intel RealSense ``.bag`` / ``.db3``
        recording (needs ``pyrealsense2``).
    camera : str, optional
        A camera preset (:data:`posedrift.camera.CAMERA_PRESETS`).
    intrinsics : Intrinsics, str ``"fx,fy,cx,cy"`` or 4 numbers, optional
        Explicit intrinsics. Without either, a RealSense recording uses its own, and
        other inputs a preset chosen by image size (320 x 240 Kinect v1 QVGA,
        640 x 480 Kinect v1 VGA, 512 x 424 Kinect v2), with a logged notice.
    depth_scale : float or str, optional
        Raw depth units per metre: 1000 (millimetres, the default for integer data),
        5000 (TUM RGB-D), or a name in :data:`DEPTH_SCALES`. Floating-point stacks are
        read as metres unless this is given; RealSense recordings carry their own.
    fps : float
        Frame rate for timestamps (``index / fps``) where the input gives none.
    unmirror : bool, optional
        Flip every frame left-right and set ``cx' = (width - 1) - cx``, for mirrored
        recordings (the person's left arm on the image's left), so that right and left
        come out as the person's own. By default True for UTD-MHAD ``.mat`` files
        (``d_depth``, which are mirrored), False otherwise. Camera presets and
        ``intrinsics`` describe the raw, unflipped images.

    Returns
    -------
    DepthSource
        With ``.intrinsics``, ``.path``, ``len()``, and iteration yielding
        :class:`~posedrift.camera.DepthFrame` or :class:`UnreadableFrame`.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        For an unknown format, an empty folder, an archive without a depth array,
        frames of a size matching neither the camera nor any preset, and similar;
        the message names the file and lists the valid choices.

    Examples
    --------
    >>> import numpy as np, tempfile, pathlib
    >>> from posedrift.io import open_depth_source
    >>> tmp = pathlib.Path(tempfile.mkdtemp())
    >>> np.save(tmp / "stack.npy", np.full((3, 240, 320), 2500, dtype=np.uint16))
    >>> source = open_depth_source(tmp / "stack.npy", camera="kinect1-qvga")
    >>> len(source), source.intrinsics.fx
    (3, 285.63)
    >>> frame = next(iter(source))
    >>> float(frame.depth[0, 0]), frame.timestamp
    (2.5, 0.0)
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"The depth input {str(path)!r} does not exist.")
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"The 'fps' option must be a positive frame rate. Got {fps!r} instead.")
    options = {"camera": camera, "intrinsics": intrinsics, "depth_scale": depth_scale, "fps": fps}
    suffix = path.suffix.lower()
    if suffix == ".mat" and not path.is_dir():
        return _open_mat(path, unmirror=unmirror, **options)
    options["unmirror"] = bool(unmirror)
    if path.is_dir():
        return PngFolderSource(path, **options)
    if suffix == ".npy":
        return _open_npy(path, **options)
    if suffix == ".npz":
        return _open_npz(path, **options)
    if suffix in (".bag", ".db3"):
        from posedrift.io._realsense import RealSenseSource

        return RealSenseSource(path, **options)
    if suffix == ".png":
        raise ValueError(
            f"{str(path)!r} is a single PNG: give the folder that holds the depth frames."
        )
    raise ValueError(
        f"Cannot tell the format of {str(path)!r}. Supported inputs: a folder of 16-bit PNG "
        f"frames, .npy, .npz, .mat (UTD-MHAD), .bag or .db3 (RealSense)."
    )
