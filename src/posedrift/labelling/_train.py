"""Training the body-part forest and net: offset bank, pixel sampling, fitting, export.

scikit-learn (the ``train`` extra) is imported only inside :func:`train_forest`;
the net (:func:`train_net`), loading and inference need NumPy alone.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from posedrift._validation import check_rng, check_scalar
from posedrift.camera import Intrinsics
from posedrift.labelling._features import BACKGROUND_DEPTH, REFERENCE_FOCAL, feature_matrix
from posedrift.labelling._forest import BodyPartForest
from posedrift.labelling._net import BodyPartNet, fit_perceptron
from posedrift.skeleton import PART_COLOURS, PART_NAMES

MAX_OFFSET = 1.3 * REFERENCE_FOCAL
"""Largest offset in pixel x metres: probes reach about 1.3 m around a pixel."""


@dataclass(frozen=True)
class LabelledFrame:
    """A depth frame with its true part labels, for training and evaluation.

    Parameters
    ----------
    depth : (H, W) float32
        Depth in metres, 0 where nothing was measured.
    labels : (H, W) uint8
        Part index + 1, 0 for background.
    intrinsics : Intrinsics
    joints : (15, 3) float, optional
        The true joints in the camera frame (metres), where known: what
        :func:`~posedrift.labelling.fit_joint_votes` learns from.
    """

    depth: np.ndarray
    labels: np.ndarray
    intrinsics: Intrinsics
    joints: np.ndarray | None = None

    @property
    def mask(self) -> np.ndarray:
        """Foreground: labelled pixels with a depth measurement."""
        return (self.labels > 0) & (self.depth > 0)


def offset_bank(
    n_offsets: int,
    *,
    max_offset: float = MAX_OFFSET,
    unary_fraction: float = 0.25,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Random candidate offset pairs ``(u_row, u_col, v_row, v_col)`` in pixel x metres.

    Each offset's length is uniform in ``[0, max_offset]`` and its direction uniform,
    so short offsets (fine detail) are as common as long ones (context). A fraction
    ``unary_fraction`` of pairs has ``v = 0``: they compare a probe with the pixel
    itself.

    Returns
    -------
    offsets : (n_offsets, 4) float32
    """
    n_offsets = check_scalar(n_offsets, "n_offsets", low=1, include_low=True, integer=True)
    rng = check_rng(rng)

    def draw(n: int) -> np.ndarray:
        length = max_offset * rng.uniform(0.0, 1.0, n)
        angle = rng.uniform(0.0, 2.0 * np.pi, n)
        return np.column_stack([length * np.sin(angle), length * np.cos(angle)])

    u = draw(n_offsets)
    v = draw(n_offsets)
    v[rng.uniform(size=n_offsets) < unary_fraction] = 0.0
    return np.hstack([u, v]).astype(np.float32)


def sample_pixels(
    labels: np.ndarray,
    mask: np.ndarray,
    n_pixels: int,
    *,
    balance: float = 0.5,
    rng: int | np.random.Generator | None = None,
) -> np.ndarray:
    """Foreground pixels drawn without replacement, favouring small parts.

    A pixel of part ``p`` is drawn with weight ``count(p) ** -balance``: 0 samples
    uniformly, 1 gives every part the same share (hands and feet as often as the torso).

    Returns
    -------
    pixels : (min(n_pixels, N_fg), 2) intp
        ``(row, column)``.
    """
    rng = check_rng(rng)
    rows, cols = np.nonzero(mask)
    if len(rows) == 0:
        return np.zeros((0, 2), dtype=np.intp)
    part = labels[rows, cols].astype(np.intp)
    counts = np.bincount(part, minlength=256).astype(float)
    weight = counts[part] ** -float(balance)
    weight /= weight.sum()
    take = min(int(n_pixels), len(rows))
    chosen = rng.choice(len(rows), size=take, replace=False, p=weight)
    chosen.sort()
    return np.column_stack([rows[chosen], cols[chosen]]).astype(np.intp)


def train_forest(
    frames: Iterable[LabelledFrame],
    *,
    n_frames: int,
    offsets: np.ndarray | None = None,
    n_offsets: int = 600,
    pixels_per_frame: int = 2000,
    balance: float = 0.5,
    n_trees: int = 3,
    max_depth: int = 20,
    min_samples_leaf: int = 5,
    max_features: float | str = "sqrt",
    extra_trees: bool = False,
    n_jobs: int = 2,
    reference_focal: float = REFERENCE_FOCAL,
    background: float = BACKGROUND_DEPTH,
    rng: int | np.random.Generator | None = None,
    on_frame: Callable[[int], None] | None = None,
    on_stage: Callable[[str], None] | None = None,
    metadata: dict | None = None,
) -> BodyPartForest:
    """Fit a body-part forest on labelled depth frames.

    Parameters
    ----------
    frames : iterable of LabelledFrame
        Consumed once; at most ``n_frames`` are used (their features are kept, the
        frames are not).
    n_frames : int
        Number of frames (sizes the feature matrix up front).
    offsets : (K, 4) float, optional
        The candidate offset bank; default :func:`offset_bank` of ``n_offsets``.
    pixels_per_frame : int
        Pixels sampled per frame (:func:`sample_pixels` with ``balance``).
    n_trees, max_depth, min_samples_leaf, max_features :
        Forest settings (scikit-learn's meanings).
    extra_trees : bool
        ExtraTreesClassifier (random thresholds, faster) instead of a random forest.
    n_jobs : int
        Threads for fitting.
    rng : int, Generator or None
        Seeds the offsets, the pixel sampling and the forest.
    on_frame, on_stage : callable, optional
        Progress callbacks: called with the frame index after each frame, and with a
        stage name (``"fit"``) before fitting.
    metadata : dict, optional
        Stored with the model (how it was trained).

    Returns
    -------
    BodyPartForest

    Raises
    ------
    ValueError
        If no frame holds a labelled pixel.
    """
    from sklearn.ensemble import ExtraTreesClassifier, RandomForestClassifier

    rng = check_rng(rng)
    offsets, x, y, data_seconds = _training_features(
        frames,
        n_frames,
        offsets,
        n_offsets=n_offsets,
        pixels_per_frame=pixels_per_frame,
        balance=balance,
        reference_focal=reference_focal,
        background=background,
        dtype=np.float32,
        rng=rng,
        on_frame=on_frame,
        caller="train_forest",
    )
    filled = len(y)
    if on_stage is not None:
        on_stage("fit")
    cls = ExtraTreesClassifier if extra_trees else RandomForestClassifier
    seed = int(rng.integers(2**31 - 1))
    estimator = cls(
        n_estimators=n_trees,
        max_depth=max_depth,
        min_samples_leaf=min_samples_leaf,
        max_features=max_features,
        n_jobs=n_jobs,
        random_state=seed,
    )
    started = time.perf_counter()
    estimator.fit(x, y)
    fit_seconds = time.perf_counter() - started
    info = dict(metadata or {})
    info.update(
        {
            "samples": int(filled),
            "offsets": len(offsets),
            "trees": n_trees,
            "max_depth": max_depth,
            "min_samples_leaf": min_samples_leaf,
            "max_features": max_features,
            "estimator": cls.__name__,
            "pixels_per_frame": pixels_per_frame,
            "balance": balance,
            "data_seconds": round(data_seconds, 1),
            "fit_seconds": round(fit_seconds, 1),
            "parts": list(PART_NAMES),
        }
    )
    return BodyPartForest.from_sklearn(
        estimator,
        offsets,
        reference_focal=reference_focal,
        background=background,
        metadata=info,
    )


def _training_features(
    frames: Iterable[LabelledFrame],
    n_frames: int,
    offsets: np.ndarray | None,
    *,
    n_offsets: int,
    pixels_per_frame: int,
    balance: float,
    reference_focal: float,
    background: float,
    dtype: type,
    rng: np.random.Generator,
    on_frame: Callable[[int], None] | None,
    caller: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The training data of a labeller: ``(offsets, x, y, seconds)``.

    ``offsets`` the bank (:func:`offset_bank` of ``n_offsets`` where none is given),
    ``x`` the sampled pixels' features ``(N, K)`` in ``dtype``, ``y`` their parts
    ``(N,)`` int16, from the first ``n_frames`` frames (:func:`sample_pixels` with
    ``balance``), and the seconds it took.
    """
    n_frames = check_scalar(n_frames, "n_frames", low=1, include_low=True, integer=True)
    if offsets is None:
        offsets = offset_bank(n_offsets, rng=rng)
    offsets = np.asarray(offsets, dtype=np.float32)
    started = time.perf_counter()
    capacity = n_frames * pixels_per_frame
    x = np.empty((capacity, len(offsets)), dtype=dtype)
    y = np.empty(capacity, dtype=np.int16)
    filled = 0
    for i, frame in enumerate(frames):
        if i >= n_frames:
            break
        mask = frame.mask
        pixels = sample_pixels(frame.labels, mask, pixels_per_frame, balance=balance, rng=rng)
        n = len(pixels)
        if n:
            direct = x.dtype == np.float32  # written in place; float16 via a float32 block
            block = feature_matrix(
                frame.depth,
                mask,
                pixels,
                offsets,
                frame.intrinsics,
                reference_focal=reference_focal,
                background=background,
                out=x[filled : filled + n] if direct else None,
            )
            if not direct:
                x[filled : filled + n] = block
            y[filled : filled + n] = frame.labels[pixels[:, 0], pixels[:, 1]].astype(np.int16) - 1
            filled += n
        if on_frame is not None:
            on_frame(i)
    if filled == 0:
        raise ValueError(f"{caller} got no labelled foreground pixel in its frames.")
    return offsets, x[:filled], y[:filled], time.perf_counter() - started


def train_net(
    frames: Iterable[LabelledFrame],
    *,
    n_frames: int,
    offsets: np.ndarray | None = None,
    n_offsets: int = 500,
    pixels_per_frame: int = 600,
    balance: float = 0.5,
    hidden: Sequence[int] = (256, 256, 128),
    epochs: int = 8,
    clip: float = 1.0,
    reference_focal: float = REFERENCE_FOCAL,
    background: float = BACKGROUND_DEPTH,
    rng: int | np.random.Generator | None = None,
    on_frame: Callable[[int], None] | None = None,
    on_epoch: Callable[[int, float], None] | None = None,
    metadata: dict | None = None,
) -> BodyPartNet:
    """Fit a body-part net (:class:`~posedrift.labelling.BodyPartNet`) on labelled frames.

    The same pixels as :func:`train_forest` draws (:func:`sample_pixels`), their
    features stored as float16 (half the memory; within the ``clip`` of 1 m that the
    net reads, float16 resolves 1 mm or finer), then
    :func:`~posedrift.labelling.fit_perceptron`.

    Parameters
    ----------
    frames : iterable of LabelledFrame
        Consumed once; at most ``n_frames`` are used.
    n_frames : int
    offsets : (K, 4) float, optional
        The offset bank; default :func:`offset_bank` of ``n_offsets``.
    pixels_per_frame, balance :
        As :func:`train_forest`'s.
    hidden, epochs :
        The perceptron's hidden widths and passes over the pixels.
    clip : float
        Metres; features are clipped to ``[-clip, clip]``.
    rng : int, Generator or None
        Seeds the offsets, the pixel sampling and the training.
    on_frame, on_epoch : callable, optional
        Progress: called with the frame index after each frame, and as
        ``on_epoch(epoch, mean_loss)`` after each epoch.
    metadata : dict, optional
        Stored with the model (how it was trained).

    Returns
    -------
    BodyPartNet

    Raises
    ------
    ValueError
        If no frame holds a labelled pixel.
    """
    rng = check_rng(rng)
    offsets, x, y, data_seconds = _training_features(
        frames,
        n_frames,
        offsets,
        n_offsets=n_offsets,
        pixels_per_frame=pixels_per_frame,
        balance=balance,
        reference_focal=reference_focal,
        background=background,
        dtype=np.float16,
        rng=rng,
        on_frame=on_frame,
        caller="train_net",
    )
    started = time.perf_counter()
    weights, biases = fit_perceptron(
        x,
        y,
        hidden=hidden,
        n_classes=len(PART_NAMES),
        clip=clip,
        epochs=epochs,
        rng=rng,
        on_epoch=on_epoch,
    )
    info = dict(metadata or {})
    info.update(
        {
            "samples": len(y),
            "offsets": len(offsets),
            "hidden": [int(h) for h in hidden],
            "epochs": int(epochs),
            "clip": float(clip),
            "pixels_per_frame": pixels_per_frame,
            "balance": balance,
            "data_seconds": round(data_seconds, 1),
            "fit_seconds": round(time.perf_counter() - started, 1),
            "parts": list(PART_NAMES),
        }
    )
    return BodyPartNet(
        offsets=offsets,
        weights=weights,
        biases=biases,
        clip=clip,
        reference_focal=reference_focal,
        background=background,
        metadata=info,
    )


def label_accuracy(
    forest: BodyPartForest | BodyPartNet, frames: Sequence[LabelledFrame]
) -> tuple[float, np.ndarray, np.ndarray]:
    """Per-pixel accuracy of ``forest`` (or a :class:`BodyPartNet`) on labelled frames.

    Returns
    -------
    accuracy : float
        Share of foreground pixels labelled with their true part (NaN if none).
    correct, total : (15,) int
        Per true part: correctly labelled and all foreground pixels.
    """
    n_parts = len(PART_NAMES)
    correct = np.zeros(n_parts, dtype=np.int64)
    total = np.zeros(n_parts, dtype=np.int64)
    for frame in frames:
        mask = frame.mask
        pred = forest.predict(frame.depth, mask, frame.intrinsics)
        truth = frame.labels[mask].astype(np.intp) - 1
        guess = pred.labels[mask]
        total += np.bincount(truth, minlength=n_parts)[:n_parts]
        correct += np.bincount(truth[guess == truth], minlength=n_parts)[:n_parts]
    accuracy = float(correct.sum() / total.sum()) if total.sum() else float("nan")
    return accuracy, correct, total


def read_label_folder(
    folder: str | Path,
    *,
    max_frames: int | None = None,
    on_skip: Callable[[str, str], None] | None = None,
) -> Iterator[tuple[str, LabelledFrame]]:
    """Frames of a folder written by ``posedrift synth``: ``(name, LabelledFrame)`` each.

    Reads ``ground_truth.json`` (intrinsics), ``depth/NNNNNN.png`` (uint16 millimetres)
    and ``labels/NNNNNN.png`` (part index + 1). A frame that cannot be used (a missing,
    empty or undecodable PNG, another bit depth or size, a label above 15) is skipped
    and the rest of the folder is still read: ``on_skip(name, reason)`` is called with
    the frame's name (``"000004.png"``) and a reason naming the file; without
    ``on_skip``, a :class:`RuntimeWarning` ``"<folder>: skipped frame <name>: <reason>"``
    is issued instead.

    Parameters
    ----------
    folder : str or Path
    max_frames : int, optional
        Read only the first ``max_frames`` depth files, in name order.
    on_skip : callable, optional
        Called as ``on_skip(name, reason)`` for each skipped frame.

    Raises
    ------
    ValueError
        If the folder's ``ground_truth.json`` cannot be read or ``depth/`` holds no PNG
        file, naming it.
    """
    import warnings

    from PIL import Image, UnidentifiedImageError

    folder = Path(folder)
    truth_path = folder / "ground_truth.json"
    try:
        intrinsics = Intrinsics.from_dict(json.loads(truth_path.read_text())["intrinsics"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(
            f"{folder} is not a folder written by 'posedrift synth': cannot read "
            f"{truth_path.name} ({exc})."
        ) from exc
    names = sorted(p.name for p in (folder / "depth").glob("*.png"))
    if not names:
        raise ValueError(f"{folder / 'depth'} holds no depth PNG frames.")
    height, width = intrinsics.shape

    def read(kind: str, name: str) -> np.ndarray:
        path = folder / kind / name
        if not path.is_file():
            raise ValueError(f"{kind}/{name} is missing")
        if path.stat().st_size == 0:
            raise ValueError(f"{kind}/{name} is empty (0 bytes)")
        try:
            with Image.open(path) as image:
                image.load()
                pixels = np.array(image)
        except UnidentifiedImageError:
            raise ValueError(f"{kind}/{name} is not an image file") from None
        except Exception as exc:  # any decoder failure: OSError, struct.error, SyntaxError...
            raise ValueError(f"{kind}/{name} cannot be decoded ({exc})") from exc
        # Pillow before 10 reads a 16-bit greyscale PNG as int32 ("I" mode).
        dtypes = (np.uint16, np.int32) if kind == "depth" else (np.uint8,)
        if pixels.ndim != 2 or pixels.dtype not in dtypes:
            expected = "16-bit (millimetres)" if kind == "depth" else "8-bit (part + 1)"
            raise ValueError(
                f"{kind}/{name} is not a {expected} greyscale PNG: read {pixels.dtype} "
                f"of shape {pixels.shape}"
            )
        if pixels.shape != (height, width):
            raise ValueError(
                f"{kind}/{name} is {pixels.shape[1]} x {pixels.shape[0]} pixels; "
                f"{truth_path.name} says {width} x {height}"
            )
        return pixels

    for name in names[:max_frames]:
        try:
            raw = read("depth", name)
            labels = read("labels", name)
            if labels.max() > len(PART_NAMES):
                raise ValueError(f"labels/{name} holds {int(labels.max())}; labels are 0..15")
        except ValueError as exc:
            if on_skip is not None:
                on_skip(name, str(exc))
            else:
                warnings.warn(f"{folder}: skipped frame {name}: {exc}", RuntimeWarning, 2)
            continue
        depth = raw.astype(np.float32) / np.float32(1000.0)
        yield name, LabelledFrame(depth, labels, intrinsics)


def colour_labels(labels: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` uint8 picture of a part-index map (-1 background: black)."""
    palette = np.vstack([np.zeros((1, 3)), np.asarray(PART_COLOURS)]).astype(np.uint8)
    return palette[np.clip(np.asarray(labels).astype(np.intp) + 1, 0, len(PART_NAMES))]


def colour_depth(depth: np.ndarray, mask: np.ndarray) -> np.ndarray:
    """``(H, W, 3)`` uint8 grey picture of the foreground depth (near: bright)."""
    out = np.zeros((*depth.shape, 3), dtype=np.uint8)
    if mask.any():
        d = depth[mask]
        lo, hi = float(d.min()), float(d.max())
        grey = 255 - 200 * (d - lo) / max(hi - lo, 1e-6)
        out[mask] = np.clip(grey, 0, 255).astype(np.uint8)[:, None]
    return out


def comparison_picture(frames: Sequence[tuple[LabelledFrame, np.ndarray]]) -> np.ndarray:
    """Rows of ``depth | truth | prediction`` pictures, one row per frame, uint8 RGB."""
    rows = []
    for frame, predicted in frames:
        mask = frame.mask
        truth = np.where(mask, frame.labels.astype(np.intp) - 1, -1)
        gap = np.full((frame.depth.shape[0], 4, 3), 255, dtype=np.uint8)
        rows.append(
            np.hstack(
                [
                    colour_depth(frame.depth, mask),
                    gap,
                    colour_labels(truth),
                    gap,
                    colour_labels(predicted),
                ]
            )
        )
        rows.append(np.full((4, rows[-1].shape[1], 3), 255, dtype=np.uint8))
    return np.vstack(rows[:-1])


DISTANCE_BANDS: tuple[tuple[float, float], ...] = ((0.0, 1.5), (1.5, 2.5), (2.5, float("inf")))
"""Bands of a frame's median person depth (metres) that accuracy is also reported in."""


def evaluate_label_folder(
    folder: str | Path,
    forest: BodyPartForest | BodyPartNet,
    *,
    max_frames: int | None = None,
    png: str | Path | None = None,
    n_pictures: int = 4,
    progress: bool = False,
    on_skip: Callable[[str, str], None] | None = None,
) -> dict:
    """Per-pixel label accuracy of ``forest`` (or a net) on a ``posedrift synth`` folder.

    The forest sees each frame's depth and the true silhouette as its mask. Frames
    that cannot be read are skipped as :func:`read_label_folder` says (``on_skip``).

    Returns
    -------
    dict
        ``{"pixel_accuracy": x, "per_part": {part: x}, "frames": n, "ms_per_frame": x,
        "by_distance": {"0-1.5m": {"pixel_accuracy": x, "frames": n}, ...}}``
        (per-part accuracy: the share of that part's pixels labelled correctly; null
        for a part never seen). ``ms_per_frame`` is the median time of ``predict``
        over the frames that show the person. ``by_distance`` splits the frames by
        their median person depth: clips where the person walks up to the camera are
        dominated by close frames, which hold many more pixels.
    """
    n_parts = len(PART_NAMES)
    correct = np.zeros(n_parts, dtype=np.int64)
    total = np.zeros(n_parts, dtype=np.int64)
    band_correct = np.zeros(len(DISTANCE_BANDS), dtype=np.int64)
    band_total = np.zeros(len(DISTANCE_BANDS), dtype=np.int64)
    band_frames = np.zeros(len(DISTANCE_BANDS), dtype=np.int64)
    times = []
    shown: list[tuple[LabelledFrame, np.ndarray]] = []
    n_frames = 0
    frames = read_label_folder(folder, max_frames=max_frames, on_skip=on_skip)
    with _progress(progress, "labelling", None) as advance:
        for _, frame in frames:
            n_frames += 1
            mask = frame.mask
            started = time.perf_counter()
            pred = forest.predict(frame.depth, mask, frame.intrinsics)
            elapsed = time.perf_counter() - started
            advance()
            if not mask.any():
                continue
            times.append(elapsed)
            truth = frame.labels[mask].astype(np.intp) - 1
            guess = pred.labels[mask]
            right = guess == truth
            total += np.bincount(truth, minlength=n_parts)[:n_parts]
            correct += np.bincount(truth[right], minlength=n_parts)[:n_parts]
            distance = float(np.median(frame.depth[mask]))
            band = next(i for i, (lo, hi) in enumerate(DISTANCE_BANDS) if lo <= distance < hi)
            band_correct[band] += int(right.sum())
            band_total[band] += len(truth)
            band_frames[band] += 1
            if np.count_nonzero(mask) >= 300:
                shown.append((frame, pred.labels))
    if png is not None and shown:
        import imageio.v3 as iio

        picked = np.linspace(0, len(shown) - 1, min(n_pictures, len(shown))).astype(int)
        Path(png).parent.mkdir(parents=True, exist_ok=True)
        iio.imwrite(png, comparison_picture([shown[i] for i in picked]))
    per_part = {
        name: (float(correct[i] / total[i]) if total[i] else None)
        for i, name in enumerate(PART_NAMES)
    }
    by_distance = {
        (f"{lo:g}-{hi:g}m" if np.isfinite(hi) else f">={lo:g}m"): {
            "pixel_accuracy": float(band_correct[i] / band_total[i]) if band_total[i] else None,
            "frames": int(band_frames[i]),
        }
        for i, (lo, hi) in enumerate(DISTANCE_BANDS)
    }
    return {
        "pixel_accuracy": float(correct.sum() / total.sum()) if total.sum() else None,
        "per_part": per_part,
        "frames": n_frames,
        "ms_per_frame": float(np.median(times) * 1e3) if times else None,
        "by_distance": by_distance,
    }


@contextmanager
def _progress(enabled: bool, description: str, total: int | None) -> Iterator[Callable[[], None]]:
    """A rich progress bar (or nothing) yielding an ``advance()`` callable."""
    if not enabled:
        yield lambda: None
        return
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        transient=False,
    ) as bar:
        task = bar.add_task(description, total=total)
        yield lambda: bar.advance(task)


@dataclass(frozen=True)
class SceneRanges:
    """Ranges the training views are drawn from (uniformly).

    Parameters
    ----------
    height : (float, float)
        Stature of the body model, metres.
    girth : (float, float)
        Girth factor of the body model.
    yaw : float
        Largest angle in degrees between the camera direction and the person's facing.
    distance : (float, float)
        Horizontal distance camera to pelvis, metres.
    camera_height : (float, float)
        Metres above the floor.
    noise_fraction : float
        Share of frames with Kinect-like noise.
    t_pose_fraction : float
        Share of frames showing a clip's first frame (the T-pose calibration pose).
    wide_fraction : float
        Share of frames from a wider set of views, as a fixed camera sees a person
        who walks about: distances ``wide_distance``, the person off the optical axis
        by up to ``wide_aim`` degrees (partly out of view at times), turned by up to
        ``wide_yaw`` degrees (side views).
    wide_distance : (float, float)
        Metres.
    wide_aim, wide_yaw : float
        Degrees.
    wide_min_yaw : float
        Degrees: the wide views' smallest turn (their turn is drawn uniformly between
        it and ``wide_yaw``, either way round). 0: any turn up to ``wide_yaw``; 120
        with ``wide_yaw`` 180: people seen from behind only.
    wide_left_side : bool
        Turn every wide view one way only, the person's left side towards the camera
        (a net for that side; :meth:`BodyPartNet.mirrored` reads the other).
    mirror_fraction : float
        Share of frames whose pose is mirrored left for right (:func:`mirror_pose`):
        every asymmetric clip pose then also appears the other way round.
    """

    height: tuple[float, float] = (1.5, 1.95)
    girth: tuple[float, float] = (0.85, 1.2)
    yaw: float = 45.0
    distance: tuple[float, float] = (2.0, 3.5)
    camera_height: tuple[float, float] = (0.7, 1.3)
    noise_fraction: float = 0.5
    t_pose_fraction: float = 0.1
    wide_fraction: float = 0.3
    wide_distance: tuple[float, float] = (1.0, 4.5)
    wide_aim: float = 25.0
    wide_yaw: float = 100.0
    wide_min_yaw: float = 0.0
    wide_left_side: bool = False
    mirror_fraction: float = 0.0

    def __post_init__(self) -> None:
        if not 0.0 <= self.wide_min_yaw <= self.wide_yaw:
            raise ValueError(
                f"The 'wide_min_yaw' of SceneRanges must lie in [0, wide_yaw = "
                f"{self.wide_yaw:g}] degrees. Got {self.wide_min_yaw!r}."
            )

    def view_yaw(self, u: float, wide: bool) -> float:
        """The person's turn in degrees for a uniform draw ``u`` in [-1, 1].

        One draw either way, so that a smallest turn or one side leaves the random
        stream as it was. A positive turn shows the person's left side.
        """
        if not wide:
            return u * self.yaw
        low = self.wide_min_yaw
        turn = low + abs(u) * (self.wide_yaw - low)
        return turn if self.wide_left_side else math.copysign(turn, u)


def mirror_pose(
    joints: np.ndarray, extras: dict[str, np.ndarray]
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """A pose reflected left for right: x negated about the pelvis, left and right swapped.

    Parameters
    ----------
    joints : (15, 3) float
        World frame (+Y up).
    extras : dict of str to (3,) float
        Named extra points (``left_hand_tip``, ``right_toe``, ...).

    Returns
    -------
    joints, extras
        The mirror image: the left hand goes where the right one was, reflected.

    Examples
    --------
    >>> from posedrift.skeleton import JOINT_INDEX, t_pose_joints
    >>> j = t_pose_joints(1.75)
    >>> j[JOINT_INDEX["left_hand"]] += [0.0, 0.3, 0.0]  # the left hand raised
    >>> m, _ = mirror_pose(j, {})
    >>> bool(m[JOINT_INDEX["right_hand"], 1] > m[JOINT_INDEX["left_hand"], 1])
    True
    """
    from posedrift.skeleton import JOINT_NAMES, other_side

    joints = np.asarray(joints, dtype=float)
    centre = 0.5 * (
        joints[JOINT_NAMES.index("left_hip"), 0] + joints[JOINT_NAMES.index("right_hip"), 0]
    )

    def reflect(p: np.ndarray) -> np.ndarray:
        q = np.array(p, dtype=float)
        q[..., 0] = 2.0 * centre - q[..., 0]
        return q

    order = [JOINT_NAMES.index(other_side(n)) for n in JOINT_NAMES]
    mirrored = reflect(joints)[order]
    extras_out = {
        name: reflect(extras[other_side(name)]) for name in extras if other_side(name) in extras
    }
    return mirrored, extras_out


def _stature(joints: np.ndarray) -> float:
    """Stature of a standing skeleton: head centre (0.935 H) above the ankles (0.039 H)."""
    from posedrift.skeleton import JOINT_INDEX

    ankle = 0.5 * (joints[JOINT_INDEX["right_foot"], 1] + joints[JOINT_INDEX["left_foot"], 1])
    return max(float(joints[JOINT_INDEX["head"], 1] - ankle) / (0.935 - 0.039), 0.5)


def random_shape(rng: np.random.Generator, ranges: SceneRanges, morph_names: Sequence[str]) -> dict:
    """Keyword arguments of ``BodyModel.with_shape``: height, girth and up to three morphs.

    ``female`` (when the body has it) on half of the bodies; up to two other morphs
    of ``morph_names`` at weights in [0, 0.8].
    """
    morphs = {}
    names = [n for n in morph_names if n != "female"]
    if "female" in morph_names and rng.uniform() < 0.5:
        morphs["female"] = float(rng.uniform(0.3, 1.0))
    if names:
        for k in rng.choice(len(names), size=int(rng.integers(0, 3)), replace=False):
            morphs[names[int(k)]] = float(rng.uniform(0.0, 0.8))
    return {
        "height": float(rng.uniform(*ranges.height)),
        "girth": float(rng.uniform(*ranges.girth)),
        "morphs": morphs,
    }


def pose_descriptors(joints: np.ndarray, stature: float) -> np.ndarray:
    """Poses made comparable: pelvis-centred, turned to face +Z, scaled to a 1.75 m stature.

    Parameters
    ----------
    joints : (T, 15, 3) float
        World frame, metres, +Y up.
    stature : float
        The skeleton's stature, metres.

    Returns
    -------
    (T, 15, 3) float
    """
    from posedrift.skeleton import JOINT_INDEX as J

    joints = np.asarray(joints, dtype=float)
    pelvis = 0.5 * (joints[:, J["right_hip"]] + joints[:, J["left_hip"]])
    rel = joints - pelvis[:, None]
    # The person's right-to-left direction (hips and shoulders) turned onto +X.
    across = (joints[:, J["left_hip"]] - joints[:, J["right_hip"]]) + (
        joints[:, J["left_shoulder"]] - joints[:, J["right_shoulder"]]
    )
    angle = np.arctan2(across[:, 2], across[:, 0])[:, None]
    cos, sin = np.cos(angle), np.sin(angle)
    turned = np.stack(
        [cos * rel[..., 0] + sin * rel[..., 2], rel[..., 1], cos * rel[..., 2] - sin * rel[..., 0]],
        axis=-1,
    )
    return turned * (1.75 / stature)


def diverse_frames(
    motions: Sequence, min_distance: float, *, rng: int | np.random.Generator | None = 0
) -> list[np.ndarray]:
    """The frames of each motion left after removing near-duplicate poses.

    Shotton et al.'s de-duplication: frames are visited in random order and kept when
    every joint-by-joint comparison with each kept pose finds some joint more than
    ``min_distance`` away (poses compared as :func:`pose_descriptors`, across all
    motions). Training on the kept frames weights each distinct pose equally, instead
    of each clip: repetitive motions (walks) shrink, varied ones keep their frames.

    Parameters
    ----------
    motions : sequence of Motion
    min_distance : float
        Metres, at a 1.75 m stature.
    rng : int, Generator or None
        Visiting order.

    Returns
    -------
    list of (K_i,) int arrays
        Sorted frame indices kept, one array per motion.

    Examples
    --------
    >>> from posedrift.synthetic import procedural_motion
    >>> motion = procedural_motion(fps=30.0)
    >>> [kept] = diverse_frames([motion], 0.05)
    >>> bool(0 < len(kept) < len(motion.joints))
    True
    """
    min_distance = check_scalar(
        min_distance, "min_distance", low=0.0, include_low=True, caller="diverse_frames"
    )
    rng = check_rng(rng)
    pool = [pose_descriptors(m.joints, _stature(np.asarray(m.joints[0]))) for m in motions]
    owner = np.concatenate([np.full(len(d), k) for k, d in enumerate(pool)])
    frame = np.concatenate([np.arange(len(d)) for d in pool])
    flat = np.concatenate(pool).reshape(len(owner), -1)
    kept = np.empty_like(flat)
    chosen = []
    limit2 = min_distance**2
    for i in rng.permutation(len(flat)):
        if chosen:
            diff = kept[: len(chosen)] - flat[i]
            far2 = (diff.reshape(len(chosen), -1, 3) ** 2).sum(axis=2).max(axis=1)
            if far2.min() <= limit2:
                continue
        kept[len(chosen)] = flat[i]
        chosen.append(i)
    chosen = np.asarray(chosen, dtype=np.intp)
    return [np.sort(frame[chosen[owner[chosen] == k]]) for k in range(len(motions))]


def _facing(joints: np.ndarray) -> np.ndarray:
    """Horizontal unit vector the person faces (from the hips; +X person's left)."""
    from posedrift.skeleton import JOINT_INDEX

    across = joints[JOINT_INDEX["left_hip"]] - joints[JOINT_INDEX["right_hip"]]
    facing = np.cross(across, [0.0, 1.0, 0.0])
    facing[1] = 0.0
    norm = np.linalg.norm(facing)
    return facing / norm if norm > 1e-9 else np.array([0.0, 0.0, 1.0])


def render_training_frame(
    joints: np.ndarray,
    extras: dict[str, np.ndarray],
    body,
    intrinsics: Intrinsics,
    *,
    yaw: float,
    distance: float,
    camera_height: float,
    aim_at_body: bool,
    noise: bool,
    rng: np.random.Generator,
    aim: float = 0.0,
) -> LabelledFrame:
    """Pose ``body`` on world ``joints`` and render it from a camera ``yaw`` degrees off
    the person's facing direction (positive: toward the person's left), ``distance``
    metres from the pelvis, looking ``aim`` degrees to the side of the person, level
    or (``aim_at_body``) down or up at the pelvis."""
    from posedrift.camera import CameraPose
    from posedrift.skeleton import pelvis_centre
    from posedrift.synthetic import kinect_noise, render

    centre = pelvis_centre(joints)
    facing = _facing(joints)
    angle = np.radians(yaw)
    direction = np.array(
        [
            facing[0] * np.cos(angle) + facing[2] * np.sin(angle),
            0.0,
            -facing[0] * np.sin(angle) + facing[2] * np.cos(angle),
        ]
    )
    eye = np.array([centre[0], camera_height, centre[2]]) + distance * direction
    target_y = float(centre[1]) if aim_at_body else camera_height
    target = np.array([centre[0], target_y, centre[2]])
    if aim:
        turn = np.radians(aim)
        look = target - eye
        look = np.array(
            [
                look[0] * np.cos(turn) + look[2] * np.sin(turn),
                look[1],
                -look[0] * np.sin(turn) + look[2] * np.cos(turn),
            ]
        )
        target = eye + look
    camera = CameraPose.look_at(eye, target)
    vertices = body.pose(joints, extras)
    out = render(
        camera.world_to_camera(vertices),
        np.asarray(body.faces),
        intrinsics,
        vertex_parts=np.asarray(body.vertex_parts),
        cull_backfaces=True,
    )
    depth, labels = out.depth, out.labels
    if noise:
        depth = kinect_noise(depth, rng=rng)
        labels = np.where(depth > 0, labels, 0).astype(np.uint8)
    return LabelledFrame(
        depth=depth, labels=labels, intrinsics=intrinsics, joints=camera.world_to_camera(joints)
    )


def synthetic_training_frames(
    n_frames: int,
    motions: Sequence,
    *,
    ranges: SceneRanges | None = None,
    intrinsics: Intrinsics | None = None,
    body=None,
    weights: Sequence[float] | None = None,
    frames: Sequence[np.ndarray] | None = None,
    min_pixels: int = 300,
    rng: int | np.random.Generator | None = None,
) -> Iterator[LabelledFrame]:
    """Rendered training frames: random poses of random bodies seen from random views.

    Each frame draws a motion (by ``weights``, default uniformly), a frame of it
    (its first, the T-pose, with probability ``ranges.t_pose_fraction``), a body
    shape, a view and noise from ``ranges``. The skeleton is scaled to the body's
    stature. Frames showing fewer than ``min_pixels`` person pixels are drawn again.

    Parameters
    ----------
    n_frames : int
    motions : sequence of Motion
        World frame: metres, +Y up, floor y = 0.
    ranges : SceneRanges, optional
    intrinsics : Intrinsics, optional
        Default the ``kinect1-qvga`` preset.
    body : BodyModel, optional
        Default :meth:`BodyModel.load_default`.
    weights : sequence of float, optional
        Relative probability of each motion.
    frames : sequence of int arrays, optional
        The frames of each motion to draw from (default all; see :func:`diverse_frames`).
    min_pixels : int
        Fewest person pixels a frame must show.
    rng : int, Generator or None

    Yields
    ------
    LabelledFrame
    """
    from posedrift.camera import camera_preset
    from posedrift.synthetic import BodyModel

    rng = check_rng(rng)
    ranges = ranges or SceneRanges()
    intrinsics = intrinsics or camera_preset("kinect1-qvga")
    base = body if body is not None else BodyModel.load_default()
    if not motions:
        raise ValueError("synthetic_training_frames needs at least one motion.")
    statures = [_stature(np.asarray(m.joints[0], dtype=float)) for m in motions]
    p = np.ones(len(motions)) if weights is None else np.asarray(weights, dtype=float)
    if p.shape != (len(motions),) or not np.all(p >= 0) or p.sum() <= 0:
        raise ValueError(
            f"The 'weights' of synthetic_training_frames must be {len(motions)} non-negative "
            f"numbers, one per motion. Got {weights!r}."
        )
    p = p / p.sum()
    if frames is not None and len(frames) != len(motions):
        raise ValueError(
            f"The 'frames' of synthetic_training_frames must hold one array per motion "
            f"({len(motions)}). Got {len(frames)}."
        )
    made = 0
    attempts = 0
    while made < n_frames:
        attempts += 1
        if attempts > 10 * n_frames + 100:
            raise ValueError("synthetic_training_frames: too many views without a person.")
        k = int(rng.choice(len(motions), p=p))
        motion = motions[k]
        if rng.uniform() < ranges.t_pose_fraction:
            t = 0
        elif frames is None or len(frames[k]) == 0:
            t = int(rng.integers(len(motion.joints)))
        else:
            t = int(frames[k][rng.integers(len(frames[k]))])
        shape = random_shape(rng, ranges, base.morph_names)
        wide = bool(rng.uniform() < ranges.wide_fraction)
        height = shape["height"]
        joints = np.asarray(motion.joints[t], dtype=float)
        extras = {name: np.asarray(v[t], dtype=float) for name, v in (motion.extras or {}).items()}
        # Drawn only when asked for, so that the default's random stream is unchanged.
        if ranges.mirror_fraction > 0 and rng.uniform() < ranges.mirror_fraction:
            joints, extras = mirror_pose(joints, extras)
        scale = height / statures[k]
        origin = np.array([joints[:, 0].mean(), 0.0, joints[:, 2].mean()])
        joints = origin + (joints - origin) * scale
        extras = {name: origin + (v - origin) * scale for name, v in extras.items()}
        shaped = base.with_shape(**shape)
        frame = render_training_frame(
            joints,
            extras,
            shaped,
            intrinsics,
            yaw=ranges.view_yaw(rng.uniform(-1.0, 1.0), wide),
            distance=rng.uniform(*(ranges.wide_distance if wide else ranges.distance)),
            camera_height=rng.uniform(*ranges.camera_height),
            aim_at_body=bool(rng.uniform() < 0.5),
            aim=rng.uniform(-ranges.wide_aim, ranges.wide_aim) if wide else 0.0,
            noise=bool(rng.uniform() < ranges.noise_fraction),
            rng=rng,
        )
        if np.count_nonzero(frame.mask) < min_pixels:
            continue
        made += 1
        yield frame


HELD_OUT_CLIPS: tuple[str, ...] = ("007_*", "131_03*")
"""Development clips kept out of training (the accuracy figure is measured on them)."""


def training_clips(
    mocap_dir: str | Path | None, *, exclude: Sequence[str] = HELD_OUT_CLIPS
) -> list[Path]:
    """The BVH files under ``mocap_dir`` whose names match no ``exclude`` glob.

    ``mocap_dir`` is a folder (searched recursively; ``.bvh`` in any letter case) or
    one BVH file.
    """
    import fnmatch

    if mocap_dir is None:
        return []
    root = Path(mocap_dir)
    if root.is_file() and root.suffix.lower() == ".bvh":
        paths = [root]
    elif root.is_dir():
        paths = sorted(p for p in root.rglob("*") if p.suffix.lower() == ".bvh" and p.is_file())
    else:
        what = "is not a BVH file or a folder" if root.exists() else "does not exist"
        raise ValueError(f"The motion capture path {str(root)!r} {what}.")
    return [p for p in paths if not any(fnmatch.fnmatch(p.name, pat) for pat in exclude)]


def load_training_motions(
    paths: Sequence[str | Path],
    *,
    procedural: bool = True,
    fps: float = 30.0,
    on_motion: Callable[[str], None] | None = None,
) -> list:
    """Motions for training: the BVH clips (resampled to ``fps``) and the procedural one.

    Raises
    ------
    ValueError
        If a BVH file cannot be read (naming it), or no motion is left.
    """
    from posedrift.synthetic import bvh_motion, procedural_motion

    motions = []
    for path in paths:
        motion = bvh_motion(path)
        motions.append(motion.resample(fps) if abs(motion.fps - fps) > 1e-9 else motion)
        if on_motion is not None:
            on_motion(Path(path).name)
    if procedural:
        motions.append(procedural_motion(fps=fps))
        if on_motion is not None:
            on_motion("procedural")
    if not motions:
        raise ValueError("No motion to train on: give BVH clips or keep the procedural motion.")
    return motions
