"""Speed of the tracker (``PoseTracker``) per stage, on one core.

A synthetic sequence (the built-in procedural motion, or BVH clips) is rendered
once; the tracker then runs over it ``repeats`` times from a fresh start. Each
frame's CPU time (``time.process_time``) is measured around
:meth:`PoseTracker.process`, and the tracker's own per-stage timings
(``FrameResult.timings_ms``) give the time of each stage. By default those stage
timings are taken in process CPU time too (``stage_clock="cpu"``: the tracker's
``time.perf_counter`` is read from ``time.process_time`` during the run), which
is far steadier than wall time on a shared machine; ``stage_clock="wall"`` keeps
the tracker's wall-clock timings.
"""

from __future__ import annotations

import contextlib
import os
import platform
import time
import types
from collections.abc import Callable, Iterator, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from posedrift._build import compiled_summary
from posedrift._threads import one_thread
from posedrift._validation import check_scalar

STAGES: tuple[str, ...] = (
    "segment",
    "points",
    "graph",
    "appearance",
    "register",
    "relabel",
    "skeleton",
    "fallback",
    "initialize",
    "total",
)
"""The tracker's stage names in ``FrameResult.timings_ms``, in pipeline order."""


@dataclass(frozen=True)
class StageTiming:
    """Timing of one stage over the frames that ran it.

    Parameters
    ----------
    stage : str
    tracked_ms : float
        Median milliseconds over tracked frames (NaN where none ran the stage).
    reinitialized_ms : float
        Median milliseconds over re-initialized frames (the first frame included).
    mean_ms : float
        Mean milliseconds per processed frame (0 where the stage did not run): these
        add up to the mean total.
    frames : int
        Frames (over all repeats) that ran the stage.
    """

    stage: str
    tracked_ms: float
    reinitialized_ms: float
    mean_ms: float
    frames: int


@dataclass(frozen=True)
class TrackBenchmark:
    """Result of :func:`bench_track`.

    Parameters
    ----------
    stages : tuple of StageTiming
        In pipeline order (``STAGES``), only stages that ran.
    cpu_ms : float
        Median over repeats of the mean CPU milliseconds per frame (all frames).
    tracked_cpu_ms, reinitialized_cpu_ms : float
        Median CPU milliseconds per tracked / re-initialized frame (NaN if none).
    wall_ms : float
        Median over repeats of the mean wall milliseconds per frame.
    repeats_cpu_ms : tuple of float
        The per-repeat means behind ``cpu_ms``.
    frames : int
        Frames per repeat (all sequences).
    status_counts : mapping of str to int
        Frames per status in the last repeat.
    n_points : int
    sequences : tuple of str
    camera : str
        Image size and focal length of the sequences' camera, and the person's distance.
    stage_clock : str
        ``"cpu"`` or ``"wall"``: the clock of the stage timings.
    threads : str
    machine : str
    """

    stages: tuple[StageTiming, ...]
    cpu_ms: float
    tracked_cpu_ms: float
    reinitialized_cpu_ms: float
    wall_ms: float
    repeats_cpu_ms: tuple[float, ...]
    frames: int
    status_counts: dict[str, int] = field(default_factory=dict)
    n_points: int = 400
    sequences: tuple[str, ...] = ()
    camera: str = ""
    stage_clock: str = "cpu"
    threads: str = ""
    machine: str = ""

    @property
    def fps(self) -> float:
        """Frames per second of CPU time, all frames."""
        return _rate(self.cpu_ms)

    @property
    def tracked_fps(self) -> float:
        """Frames per second of CPU time, tracked frames (median frame)."""
        return _rate(self.tracked_cpu_ms)

    @property
    def reinitialized_fps(self) -> float:
        """Frames per second of CPU time, re-initialized frames (median frame)."""
        return _rate(self.reinitialized_cpu_ms)

    def to_dict(self) -> dict:
        """As JSON-ready values (NaN as None), with the frame rates."""
        out = asdict(self)
        out["stages"] = [asdict(s) for s in self.stages]
        out["fps"] = self.fps
        out["tracked_fps"] = self.tracked_fps
        out["reinitialized_fps"] = self.reinitialized_fps
        return _jsonable(out)

    def markdown(self) -> str:
        """The per-stage table and the frame rates, as Markdown."""
        lines = [
            f"posedrift bench track: {self.frames} frames x {len(self.repeats_cpu_ms)} repeats, "
            f"{self.n_points} points, {', '.join(self.sequences)}; {self.camera}; "
            f"stage clock {self.stage_clock}; "
            f"{self.threads}",
            "",
            "| stage | tracked median ms | reinit median ms | mean ms/frame |",
            "|---|---:|---:|---:|",
        ]
        for s in self.stages:
            lines.append(
                f"| {s.stage} | {_fmt(s.tracked_ms)} | {_fmt(s.reinitialized_ms)} | "
                f"{_fmt(s.mean_ms)} |"
            )
        counts = ", ".join(f"{k} {v}" for k, v in sorted(self.status_counts.items()))
        lines += [
            "",
            "| frames | CPU ms/frame | fps (CPU) |",
            "|---|---:|---:|",
            f"| all (mean) | {_fmt(self.cpu_ms)} | {_fmt(self.fps, 1)} |",
            f"| tracked (median) | {_fmt(self.tracked_cpu_ms)} | {_fmt(self.tracked_fps, 1)} |",
            f"| re-initialized (median) | {_fmt(self.reinitialized_cpu_ms)} | "
            f"{_fmt(self.reinitialized_fps, 1)} |",
            "",
            f"wall {self.wall_ms:.2f} ms/frame; statuses (last repeat): {counts}; "
            f"per-repeat CPU ms/frame: {', '.join(f'{t:.2f}' for t in self.repeats_cpu_ms)}",
        ]
        if self.machine:
            lines.append(f"machine: {self.machine}")
        return "\n".join(lines)


def _rate(ms: float) -> float:
    return 1000.0 / ms if np.isfinite(ms) and ms > 0 else float("nan")


def _fmt(value: float, digits: int = 2) -> str:
    return "-" if not np.isfinite(value) else f"{value:.{digits}f}"


def _jsonable(value):
    if isinstance(value, dict):
        return {k: _jsonable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_jsonable(v) for v in value]
    if isinstance(value, float) and not np.isfinite(value):
        return None
    return value


@contextlib.contextmanager
def _stage_clock(kind: str) -> Iterator[str]:
    """Make the tracker's stage timings read CPU time (``kind="cpu"``) for the block.

    Yields the clock in effect: ``"wall"`` where the tracker's timer cannot be redirected.
    """
    from posedrift.tracking import _tracker

    saved = getattr(_tracker, "time", None)
    if kind == "wall" or not isinstance(saved, types.ModuleType):
        yield "wall"
        return
    names = [k for k in dir(time) if not k.startswith("_")]
    shim = types.SimpleNamespace(**{k: getattr(time, k) for k in names})
    shim.perf_counter = time.process_time
    _tracker.time = shim
    try:
        yield "cpu"
    finally:
        _tracker.time = saved


def render_sequences(
    bvh: Sequence[str | os.PathLike] = (),
    *,
    frames: int = 150,
    intrinsics=None,
    distance: float | None = None,
    room: bool = False,
    on_frame: Callable[[int, int], None] | None = None,
):
    """The benchmark's sequences: the built-in procedural motion, or BVH clips.

    Parameters
    ----------
    bvh : sequence of paths
        BVH clips; empty for the built-in motion.
    frames : int
        Frames rendered per sequence (fewer where a clip is shorter).
    intrinsics : Intrinsics, optional
        The camera (default: Kinect v1 at 320 x 240, as in the evaluation protocol).
    distance : float, optional
        The person's distance from the camera in metres (default: the protocol's).
    room : bool
        Render the floor and a wall behind the person, with Kinect-like depth noise,
        as a real camera sees a person (default: the person alone, noise-free).
    on_frame : callable, optional
        ``on_frame(done, total)`` progress callback of the renderer.

    Returns
    -------
    list of EvaluationSequence
    """
    from posedrift.synthetic import build_sequence, bvh_motion, procedural_motion

    frames = check_scalar(frames, "frames", low=1, include_low=True, integer=True)
    placement = {"background": True, "noise": True} if room else {}
    if intrinsics is not None:
        placement["intrinsics"] = intrinsics
    if distance is not None:
        placement["distance"] = check_scalar(distance, "distance", low=0.0)
    out = []
    if not bvh:
        motions = [("builtin", procedural_motion(fps=30.0))]
    else:
        motions = []
        for path in bvh:
            path = Path(path)
            if not path.is_file():
                raise ValueError(f"The BVH file {path} does not exist.")
            motions.append((path.stem, bvh_motion(path)))
    for name, motion in motions:
        out.append(
            build_sequence(
                motion,
                n_frames=min(frames, len(motion)),
                in_place=True,
                rng=0,
                name=name,
                on_frame=on_frame,
                **placement,
            )
        )
    return out


def bench_track(
    sequences=None,
    *,
    frames: int = 150,
    n_points: int = 400,
    repeats: int = 3,
    stage_clock: str = "cpu",
    tracker_options: dict | None = None,
    scene: str = "",
) -> TrackBenchmark:
    """Time :class:`posedrift.tracking.PoseTracker` per stage on one thread.

    Parameters
    ----------
    sequences : list of EvaluationSequence, optional
        From :func:`render_sequences`; the built-in motion (``frames`` frames) when None.
    frames : int
        Frames of the built-in motion when ``sequences`` is None.
    n_points : int
        The tracker's points per frame.
    repeats : int
        Runs over the sequences, each with a fresh tracker (after an untimed warm-up
        on the first frames); the CPU figures are medians over the repeats (per-frame
        medians pool the frames of all repeats).
    stage_clock : {"cpu", "wall"}
        The clock of the per-stage timings.
    tracker_options : dict, optional
        Extra keyword arguments of ``PoseTracker``.
    scene : str
        What else the frames show (``"room"`` for :func:`render_sequences`'s ``room``),
        recorded with the camera.

    Returns
    -------
    TrackBenchmark

    Examples
    --------
    >>> from posedrift.benchmarks import bench_track
    >>> bench_track(frames=2, repeats=1).frames
    2
    """
    from posedrift.labelling import BodyPartForest
    from posedrift.tracking import PoseTracker

    n_points = check_scalar(n_points, "n_points", low=20, include_low=True, integer=True)
    repeats = check_scalar(repeats, "repeats", low=1, include_low=True, integer=True)
    if stage_clock not in ("cpu", "wall"):
        raise ValueError(f"The 'stage_clock' must be 'cpu' or 'wall'. Got {stage_clock!r}.")
    if sequences is None:
        sequences = render_sequences(frames=frames)
    sequences = [s for s in sequences if len(s.frames)]
    if not sequences:
        raise ValueError("The benchmark needs at least one sequence with frames.")
    options = {"n_points": n_points, **(tracker_options or {})}
    try:
        BodyPartForest.load_default()  # loaded once, outside the timings
    except ValueError:  # pragma: no cover - the tracker falls back on geometry
        pass
    stage_times: dict[str, dict[str, list[float]]] = {s: {} for s in STAGES}
    cpu_by_status: dict[str, list[float]] = {}
    repeat_cpu, repeat_wall = [], []
    n_frames = sum(len(s.frames) for s in sequences)
    counts: dict[str, int] = {}
    with one_thread() as threads, _stage_clock(stage_clock) as clock:
        # Warm-up, not timed: first-call imports and caches.
        warm = PoseTracker(sequences[0].frames[0].intrinsics, **options)
        for frame in sequences[0].frames[:3]:
            warm.process(frame)
        for _ in range(repeats):
            counts = {}
            cpu_total = wall_total = 0.0
            for seq in sequences:
                tracker = PoseTracker(seq.frames[0].intrinsics, **options)
                for frame in seq.frames:
                    wall, cpu = time.perf_counter(), time.process_time()
                    result = tracker.process(frame)
                    cpu = 1e3 * (time.process_time() - cpu)
                    wall_total += 1e3 * (time.perf_counter() - wall)
                    cpu_total += cpu
                    status = result.status.value
                    counts[status] = counts.get(status, 0) + 1
                    cpu_by_status.setdefault(status, []).append(cpu)
                    for stage, ms in result.timings_ms.items():
                        stage_times.setdefault(stage, {}).setdefault(status, []).append(ms)
            repeat_cpu.append(cpu_total / n_frames)
            repeat_wall.append(wall_total / n_frames)
    total_frames = n_frames * repeats
    stages = []
    for stage, by_status in stage_times.items():
        if not by_status:
            continue
        every = [v for values in by_status.values() for v in values]
        stages.append(
            StageTiming(
                stage=stage,
                tracked_ms=_median(by_status.get("tracked")),
                reinitialized_ms=_median(by_status.get("reinitialized")),
                mean_ms=float(np.sum(every) / total_frames),
                frames=len(every),
            )
        )
    return TrackBenchmark(
        stages=tuple(stages),
        cpu_ms=float(np.median(repeat_cpu)),
        tracked_cpu_ms=_median(cpu_by_status.get("tracked")),
        reinitialized_cpu_ms=_median(cpu_by_status.get("reinitialized")),
        wall_ms=float(np.median(repeat_wall)),
        repeats_cpu_ms=tuple(round(t, 3) for t in repeat_cpu),
        frames=n_frames,
        status_counts=counts,
        n_points=n_points,
        sequences=tuple(str(s.name) for s in sequences),
        camera=_camera_text(sequences[0]) + (f", {scene}" if scene else ""),
        stage_clock=clock,
        threads=threads,
        machine=f"{platform.processor() or platform.machine()} ({simd_level()}), Python "
        f"{platform.python_version()}, NumPy {np.__version__}, {compiled_summary()}",
    )


def simd_level() -> str:
    """The widest vector instructions NumPy found on this processor ("AVX-512", "AVX2"...).

    Speed depends on it more than on the clock: NumPy's float64 ``exp`` and the
    compiled kernels' clones are vectorized for AVX-512 or AVX2 (docs/results-log.md).
    """
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # NumPy moved its private table: say so rather than guess
        return "SIMD unknown"
    for name, label in (("AVX512F", "AVX-512"), ("AVX2", "AVX2"), ("ASIMD", "NEON")):
        if features.get(name):
            return label
    return "no AVX2"


def _camera_text(sequence) -> str:
    """``"320x240 px, fx 285.6, person 2.8 m away"`` for a rendered sequence."""
    k = sequence.frames[0].intrinsics
    text = f"{k.width}x{k.height} px, fx {k.fx:.1f}"
    joints = getattr(sequence.reference, "joints", None)
    if joints is not None and len(joints):
        text += f", person {float(np.nanmedian(joints[:, :, 2])):.1f} m away"
    return text


def _median(values: list[float] | None) -> float:
    return float(np.median(values)) if values else float("nan")
