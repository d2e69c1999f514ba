"""The evaluation harness: every method on the same frames, in one run.

Methods receive the depth frames (and, through them, the intrinsics) and nothing
else; the reference goes to the metrics only. Each method is built by a factory
registered in :data:`METHODS`, for each sequence afresh, with one body-part forest
(and one body-part net) shared by all of them (loaded once).
"""

from __future__ import annotations

import logging
import time
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np

from posedrift._threads import blas_limited
from posedrift._validation import check_scalar
from posedrift.camera import DepthFrame, Intrinsics, project
from posedrift.evaluation._metrics import (
    angle_agreement,
    angle_errors,
    angles_in_view,
    angles_seen,
    failed_frames,
    fill_forward,
    map_at,
    mpjpe_mm,
)
from posedrift.evaluation._types import EvaluationSequence, Reference
from posedrift.skeleton import CONVENTIONS, facing_yaw, joint_angles, to_convention
from posedrift.tracking import FrameResult, FrameStatus, PoseMethod, smooth_results

logger = logging.getLogger(__name__)

MethodFactory = Callable[..., PoseMethod]
"""``factory(intrinsics, *, forest) -> PoseMethod``; a factory whose attribute
``seeded`` is true also takes ``rng=`` (the seed of the method's random point
sampling: :func:`run_methods`' ``seed``), and one whose attribute ``takes_part_net``
is true takes ``part_net=`` (the shared body-part net)."""


def _tracker(**options: Any) -> MethodFactory:
    def factory(
        intrinsics: Intrinsics, *, forest: Any = None, part_net: Any = None, rng: int = 0
    ) -> PoseMethod:
        from posedrift.tracking import PoseTracker

        kwargs = {"part_net": part_net, **options}
        return PoseTracker(intrinsics, forest=forest, rng=rng, **kwargs)

    factory.seeded = True  # type: ignore[attr-defined]
    factory.takes_part_net = True  # type: ignore[attr-defined]
    return factory


def _frontal_net(nets: Any) -> Any:
    """A FacingNets' frontal net (or the one net given): no turned, high, back or side net."""
    return getattr(nets, "frontal", nets)


def _without_back_net(nets: Any) -> Any:
    """A FacingNets without its back net (the turned net labels every turned view)."""
    from posedrift.labelling import FacingNets

    return replace(nets, back=None) if isinstance(nets, FacingNets) else nets


def _without_side_net(nets: Any) -> Any:
    """A FacingNets without its side net (the turned net labels every side view)."""
    from posedrift.labelling import FacingNets

    return replace(nets, side=None) if isinstance(nets, FacingNets) else nets


def _tracker_with_nets(choose: Callable[[Any], Any]) -> MethodFactory:
    """The tracker with ``choose(shared part nets)`` labelling its pixels."""
    whole = _tracker()

    def factory(
        intrinsics: Intrinsics, *, forest: Any = None, part_net: Any = None, rng: int = 0
    ) -> PoseMethod:
        if part_net is None:
            from posedrift.labelling import FacingNets

            part_net = FacingNets.load_default()
        return whole(intrinsics, forest=forest, part_net=choose(part_net), rng=rng)

    factory.seeded = True  # type: ignore[attr-defined]
    factory.takes_part_net = True  # type: ignore[attr-defined]
    return factory


def _baseline(
    class_name: str, *, seeded: bool = False, tracker_loop: bool = False, net_labels: bool = False
) -> MethodFactory:
    """A baseline of :mod:`posedrift.baselines`. One that runs the tracker's loop
    (``tracker_loop``) labels pixels as the tracker does (``part_net`` passed on); a
    per-frame one with the forest, as its paper does, or with ``net_labels`` the part net."""

    def factory(
        intrinsics: Intrinsics, *, forest: Any = None, part_net: Any = None, rng: int = 0
    ) -> PoseMethod:
        import posedrift.baselines as baselines

        options: dict[str, Any] = {"rng": rng} if seeded else {}
        if tracker_loop:
            options["part_net"] = part_net
        if net_labels and part_net is None:
            from posedrift.labelling import BodyPartNet

            forest = BodyPartNet.load_default()
        elif net_labels and not isinstance(part_net, str):  # "none": the forest labels
            forest = part_net
        return getattr(baselines, class_name)(intrinsics, forest=forest, **options)

    factory.seeded = seeded  # type: ignore[attr-defined]
    factory.takes_part_net = True  # type: ignore[attr-defined]
    return factory


def _is_seeded(factory: MethodFactory) -> bool:
    """Whether a method samples at random (its factory takes ``rng``): worth repeating."""
    return bool(getattr(factory, "seeded", False))


def _takes_part_net(factory: MethodFactory) -> bool:
    """Whether a factory takes ``part_net=`` (those of :data:`METHODS` do)."""
    return bool(getattr(factory, "takes_part_net", False))


METHODS: dict[str, tuple[str, MethodFactory]] = {
    "cpd": ("the tracker: nonrigid CPD, relabelling, warm start, 400 points", _tracker()),
    "shotton": (
        "Shotton et al. 2011 per frame: forest labels, mean shift",
        _baseline("ShottonBaseline"),
    ),
    "shotton-net": (
        "Shotton et al.'s per-frame joints from the part net's labels instead of the forest's",
        _baseline("ShottonBaseline", net_labels=True),
    ),
    "pda": ("Dinh et al. 2014 per frame: principal directions of parts", _baseline("PDABaseline")),
    "icp": (
        "the tracking loop with nearest-neighbour (ICP) correspondences",
        _baseline("ICPTracker", seeded=True, tracker_loop=True),
    ),
    "cpd-frontal": (
        "ablation: the frontal part net alone, for every view (no turned net)",
        _tracker_with_nets(_frontal_net),
    ),
    "cpd-noback": (
        "ablation: the turned net for every turned view, the back too (no back net)",
        _tracker_with_nets(_without_back_net),
    ),
    "cpd-noside": (
        "ablation: the turned net for every side view (no side net)",
        _tracker_with_nets(_without_side_net),
    ),
    "cpd-forest": (
        "ablation: the forest labels the pixels, no part net (the tracker before the net)",
        _tracker(part_net="none"),
    ),
    "cpd-paper": (
        "ablation: the paper's pure tracking, no per-frame forest evidence",
        _tracker(appearance_weight=0.0, vote_weights=(0.0, 0.0)),
    ),
    "icp-paper": (
        "ablation: the pure tracking with ICP correspondences, no per-frame forest evidence",
        _tracker(correspondence="icp", appearance_weight=0.0, vote_weights=(0.0, 0.0)),
    ),
    "cpd-norelabel": ("ablation: no geodesic relabelling", _tracker(relabel=False)),
    "cpd-novotes": (
        "ablation: no joint votes (the skeleton from the labels alone)",
        _tracker(vote_weights=(0.0, 0.0)),
    ),
    "cpd-rigid": ("ablation: rigid instead of nonrigid CPD", _tracker(registration="rigid")),
    "cpd-cold": ("ablation: no warm start of CPD", _tracker(warm_start=False)),
    "cpd-reinit": (
        "ablation: a failed track always replaced by a healthy re-initialization",
        _tracker(keep_better_track=False),
    ),
    "cpd-nofallback": (
        "ablation: CPD alone, without the ICP second opinion on doubtful frames",
        _tracker(icp_fallback=None),
    ),
    "cpd-level": (
        "ablation: every camera taken for level (no tilt measured, no high net)",
        _tracker(measure_tilt=False),
    ),
    "cpd-nobrace": (
        "ablation: the hips where the thighs put them (no braced pelvis)",
        _tracker(brace_pelvis=False),
    ),
    "cpd-nohold": (
        "ablation: joints outside the image from the prediction (no trunk continued, no "
        "limbs held)",
        _tracker(hold_unseen=False),
    ),
    "cpd-noislands": (
        "ablation: stray upper-arm points fitted as labelled (no islands merged)",
        _tracker(merge_islands=False),
    ),
    "cpd-200": ("ablation: 200 points", _tracker(n_points=200)),
    "cpd-400": ("ablation: 400 points (the default)", _tracker(n_points=400)),
    "cpd-800": ("ablation: 800 points", _tracker(n_points=800)),
    "cpd-fullres": (
        "ablation: every pixel of a 640 x 480 camera (no decimation)",
        _tracker(decimation=1),
    ),
}
"""Method name -> (description, factory ``f(intrinsics, *, forest, part_net) -> PoseMethod``)."""

DEFAULT_METHODS: tuple[str, ...] = ("cpd", "shotton", "pda", "icp")


def parse_methods(text: str | Sequence[str]) -> list[str]:
    """``"cpd,shotton"`` (or a list) -> checked method names, in order, without repeats.

    Raises
    ------
    ValueError
        If a name is unknown; the message lists the valid ones.
    """
    names = [n.strip() for n in text.split(",")] if isinstance(text, str) else list(text)
    names = [n for n in names if n]
    if not names:
        raise ValueError(f"No method given. Valid methods: {', '.join(METHODS)}.")
    unknown = [n for n in names if n not in METHODS]
    if unknown:
        raise ValueError(f"Unknown method(s) {unknown}. Valid methods: {', '.join(METHODS)}.")
    return list(dict.fromkeys(names))


def make_method(
    name: str, intrinsics: Intrinsics, *, forest: Any = None, part_net: Any = None
) -> PoseMethod:
    """Build a registered method for one camera.

    Parameters
    ----------
    name : str
        A key of :data:`METHODS` (``cpd``, ``shotton``, ``pda``, ``icp``, ``cpd-rigid``...).
    intrinsics : Intrinsics
    forest : BodyPartForest, optional
        Shared by all methods; each loads the default model when None.
    part_net : BodyPartNet or FacingNets, optional
        Shared by the methods that label pixels with it; the shipped nets when None.
    """
    (name,) = parse_methods([name])
    return METHODS[name][1](intrinsics, forest=forest, part_net=part_net)


@dataclass
class MethodRun:
    """One method's results on one sequence (what the metrics and figures need)."""

    method: str
    sequence: str
    results: list[FrameResult]
    seconds: float
    label_hits: int = 0
    label_total: int = 0
    errors: list[str] = field(default_factory=list)
    relabel: dict[int, tuple[np.ndarray, np.ndarray, np.ndarray]] = field(default_factory=dict)
    """For ``cpd`` with ``keep_frames``: per frame, (points, labels before, after relabelling)."""

    @property
    def joints(self) -> np.ndarray:
        """``(T, 15, 3)`` metres, NaN in failed frames."""
        return np.stack([r.joints for r in self.results])

    @property
    def angles(self) -> np.ndarray:
        """``(T, 8)`` degrees, from the joints (``FrameResult.angles``)."""
        return joint_angles(self.joints)


@dataclass
class SequenceRecord:
    """What the evaluation keeps of a sequence: its reference, and its frames for figures."""

    name: str
    reference: Reference
    intrinsics: Intrinsics
    frames: tuple[DepthFrame, ...] | None = None
    angles_seen: np.ndarray | None = None
    """``(T, 8)`` bool: the reference's angles whose joints the frames show
    (:func:`~posedrift.evaluation.angles_seen`)."""


@dataclass
class EvaluationRun:
    """Everything one evaluation produced: per method, per sequence."""

    protocol: str
    sequences: list[SequenceRecord]
    methods: list[str]
    runs: dict[tuple[str, str], MethodRun]
    forest: Any = None
    skipped: list[tuple[str, str]] = field(default_factory=list)
    """(name, reason) of each sequence left out (see :func:`run_methods`)."""


def label_hits(result: FrameResult, labels: np.ndarray, intrinsics: Intrinsics) -> tuple[int, int]:
    """Labelled points of a result whose label matches the ground-truth label image.

    Each point is projected to its pixel; points that land off the image or on
    ground-truth background are not counted.

    Returns
    -------
    hits, total : int
    """
    if len(result.points) == 0 or len(result.labels) != len(result.points):
        return 0, 0
    uv = np.rint(project(result.points, intrinsics)).astype(np.int64, copy=False)
    h, w = labels.shape
    inside = (uv[:, 0] >= 0) & (uv[:, 0] < w) & (uv[:, 1] >= 0) & (uv[:, 1] < h)
    truth = np.zeros(len(uv), dtype=np.int64)
    truth[inside] = labels[uv[inside, 1], uv[inside, 0]]
    counted = inside & (truth > 0)
    hits = int(np.count_nonzero(truth[counted] == result.labels[counted] + 1))
    return hits, int(np.count_nonzero(counted))


def _progress(enabled: bool, total: int):
    from rich.console import Console
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    return Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=Console(stderr=True),
        disable=not enabled,
        transient=False,
    )


def unusable_reason(sequence: EvaluationSequence, done: Iterable[str] = ()) -> str | None:
    """Why a sequence cannot be evaluated, or None if it can.

    A sequence cannot be evaluated if it has no frames, if no frame of its
    reference has all 15 joints finite (every error would be undefined), or if its
    name is among ``done`` (the names already evaluated: a second sequence of the
    same name would overwrite the first one's results).

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.evaluation import EvaluationSequence, Reference
    >>> empty = Reference(joints=np.zeros((0, 15, 3)), angles=np.zeros((0, 8)))
    >>> unusable_reason(EvaluationSequence(name="x", frames=(), reference=empty))
    'it has no frames'
    """
    if len(sequence.frames) == 0:
        return "it has no frames"
    joints = np.asarray(sequence.reference.joints, dtype=float)
    if not np.isfinite(joints).all(axis=(1, 2)).any():
        return (
            f"its reference has no usable frame (in none of its {len(joints)} frames are all "
            f"{joints.shape[1]} joints finite)"
        )
    if sequence.name in set(done):
        return "a sequence of the same name was already evaluated in this run"
    return None


def _warn_skip(name: str, reason: str) -> None:
    warnings.warn(f"skipped sequence {name!r}: {reason}", RuntimeWarning, stacklevel=3)


def run_methods(
    sequences: Iterable[EvaluationSequence],
    methods: Sequence[str] | Mapping[str, MethodFactory] = DEFAULT_METHODS,
    *,
    forest: Any = None,
    part_net: Any = None,
    progress: bool = True,
    protocol: str | None = None,
    keep_frames: bool = False,
    on_skip: Callable[[str, str], None] | None = None,
    seed: int = 0,
    smooth: float = 0.0,
    smooth_lag: float | None = None,
) -> EvaluationRun:
    """Run every method over every sequence, the same frames for all.

    A sequence that cannot be evaluated (:func:`unusable_reason`: no frames, no
    usable reference frame, or a name already evaluated) is left out, reported as
    ``on_skip(name, reason)`` and listed in ``EvaluationRun.skipped``; the others
    are still evaluated.

    Parameters
    ----------
    sequences : iterable of EvaluationSequence
        Consumed one at a time (a generator keeps only one sequence's frames in
        memory unless ``keep_frames``).
    methods : sequence of str, or mapping of name -> factory
        Names from :data:`METHODS`, or factories ``f(intrinsics, *, forest)`` (given
        ``part_net=`` too where the factory's attribute ``takes_part_net`` is true, as
        for those of :data:`METHODS`).
    forest : BodyPartForest, optional
        Shared by all methods. When None, the default model is loaded once here
        (if the package has one) and shared.
    part_net : BodyPartNet, FacingNets or "none", optional
        The part net of the methods that label pixels with one (the trackers,
        ``shotton-net``, which labels as a pair's frontal net); when None the shipped
        pair (``FacingNets.load_default()``) is loaded once here and shared.
    progress : bool
        Draw a progress bar on standard error.
    protocol : str, optional
        ``"synthetic"`` or ``"utd"``; inferred from the references by default.
    keep_frames : bool
        Keep the depth frames in the result (for figures).
    on_skip : callable, optional
        ``on_skip(name, reason)`` for each sequence left out; by default a
        ``RuntimeWarning`` naming it.
    seed : int
        Seed of the random point sampling of the methods that have one (the
        trackers: factories marked ``seeded``); the others run as they are.
    smooth : float
        Seconds: every method's joints smoothed offline over each whole sequence
        (:func:`posedrift.tracking.smooth_results`) before they are scored; 0 scores
        them as the methods gave them, frame by frame.
    smooth_lag : float, optional
        Seconds: smooth each frame with the frames at most this long after it (the
        latency of :class:`posedrift.tracking.LiveSmoother` on a live stream); None
        uses the whole window.

    Returns
    -------
    EvaluationRun

    Raises
    ------
    ValueError
        If no sequence could be evaluated ("No sequence to evaluate...").
    """
    factories = _factories(methods)
    if forest is None:
        forest = _default_forest()
    if part_net is None:
        part_net = _default_part_net()
    total = None
    if isinstance(sequences, Sequence):
        total = sum(len(s.frames) for s in sequences) * len(factories)
    runs: dict[tuple[str, str], MethodRun] = {}
    records: list[SequenceRecord] = []
    skipped: list[tuple[str, str]] = []
    report_skip = _warn_skip if on_skip is None else on_skip
    # One BLAS thread for every method, as the tracker takes by default: their frames
    # per second then compare, whatever else the machine runs.
    with _progress(progress, total) as bar, blas_limited(1):
        task = bar.add_task("evaluating", total=total)
        for seq in sequences:
            reason = unusable_reason(seq, (r.name for r in records))
            if reason is not None:
                skipped.append((seq.name, reason))
                report_skip(seq.name, reason)
                continue
            intrinsics = seq.frames[0].intrinsics
            labels = seq.reference.labels
            for name, factory in factories.items():
                run_name = f"{name}, seed {seed}" if seed else name
                bar.update(task, description=f"{seq.name}: {run_name}")
                seeded = {"rng": seed} if _is_seeded(factory) else {}
                # Factories of one's own, f(intrinsics, *, forest), get no part_net.
                shared_net = {"part_net": part_net} if _takes_part_net(factory) else {}
                method = factory(intrinsics, forest=forest, **shared_net, **seeded)
                run = MethodRun(method=name, sequence=seq.name, results=[], seconds=0.0)
                observer = None
                if keep_frames and name == "cpd":
                    from posedrift.evaluation._figures import observe_relabel

                    observer = observe_relabel().__enter__()
                for frame in seq.frames:
                    if observer is not None:
                        observer.calls.clear()
                    start = time.perf_counter()
                    try:
                        result = method.process(frame)
                    except Exception as exc:  # a method's failure is a failed frame, reported
                        result = FrameResult.empty(
                            frame.index, FrameStatus.LOST, f"{type(exc).__name__}: {exc}"
                        )
                        if len(run.errors) < 5:
                            logger.warning(
                                "%s failed on %s frame %d: %s", name, seq.name, frame.index, exc
                            )
                        run.errors.append(f"frame {frame.index}: {type(exc).__name__}: {exc}")
                    run.seconds += time.perf_counter() - start
                    run.results.append(result)
                    if observer is not None and observer.calls:
                        run.relabel[frame.index] = observer.calls[-1]
                    if labels is not None:
                        hits, counted = label_hits(result, labels[frame.index], intrinsics)
                        run.label_hits += hits
                        run.label_total += counted
                    bar.advance(task)
                if observer is not None:
                    observer.__exit__(None, None, None)
                run.results = smooth_results(run.results, smooth, lag=smooth_lag, fps=seq.fps)
                runs[(name, seq.name)] = run
            records.append(
                SequenceRecord(
                    name=seq.name,
                    reference=seq.reference,
                    intrinsics=intrinsics,
                    frames=seq.frames if keep_frames else None,
                    angles_seen=angles_seen(
                        seq.reference.joints, [f.depth for f in seq.frames], intrinsics
                    ),
                )
            )
    if not records:
        raise ValueError(
            f"No sequence to evaluate ({len(skipped)} skipped)."
            if skipped
            else "No sequence to evaluate."
        )
    if protocol is None:
        kinds = {r.reference.kind for r in records}
        protocol = "synthetic" if kinds == {"synthetic"} else "utd"
    return EvaluationRun(
        protocol=protocol,
        sequences=records,
        methods=list(factories),
        runs=runs,
        forest=forest,
        skipped=skipped,
    )


def _factories(methods: Sequence[str] | Mapping[str, MethodFactory]) -> dict[str, MethodFactory]:
    """Method name -> factory, from names (:data:`METHODS`) or a mapping."""
    if isinstance(methods, Mapping):
        return dict(methods)
    return {name: METHODS[name][1] for name in parse_methods(methods)}


def mean_of_repeats(rows: Sequence[Mapping]) -> dict:
    """One method's report rows from repeated runs (seeds 0, 1, ...) -> their mean row.

    Every number is the mean over the runs (counts rounded to whole numbers; None
    where any run has None), and ``"repeats"`` says how the mean angle error spread:
    ``{"seeds": [...], "angle_error_mean_deg": [one per run], "sd_deg": sample
    standard deviation}``.

    Examples
    --------
    >>> runs = ((4.0, 1), (6.0, 2))
    >>> rows = [{"angle_error_deg": {"mean": m}, "failed_frames": f} for m, f in runs]
    >>> mean_of_repeats(rows)["angle_error_deg"], mean_of_repeats(rows)["failed_frames"]
    ({'mean': 5.0}, 2)
    >>> mean_of_repeats(rows)["repeats"]["sd_deg"]
    1.4142
    """
    out = _mean_tree(list(rows))
    means = [float(row["angle_error_deg"]["mean"]) for row in rows]
    out["repeats"] = {
        "seeds": list(range(len(rows))),
        "angle_error_mean_deg": [_round(m) for m in means],
        "sd_deg": _round(np.std(means, ddof=1)) if len(means) > 1 else 0.0,
    }
    return out


def _mean_tree(values: list) -> Any:
    """The mean of equally shaped JSON trees, leaf by leaf (see :func:`mean_of_repeats`)."""
    first = values[0]
    if isinstance(first, Mapping):
        return {key: _mean_tree([v[key] for v in values]) for key in first}
    if any(v is None for v in values) or isinstance(first, (bool, str, list)):
        return None if any(v is None for v in values) else first
    mean = float(np.mean(values))
    return round(mean) if isinstance(first, int) else _round(mean)


def _default_forest() -> Any:
    try:
        from posedrift.labelling import BodyPartForest
    except ImportError:
        return None
    return BodyPartForest.load_default()


def _default_part_net() -> Any:
    """The shipped part nets (:meth:`FacingNets.load_default`), or "none" (the forest
    labels) where they cannot be loaded."""
    from posedrift.labelling import FacingNets

    try:
        return FacingNets.load_default()
    except ValueError:
        return "none"


def _status_counts(runs: list[MethodRun]) -> dict[str, int]:
    counts = dict.fromkeys((s.value for s in FrameStatus), 0)
    for run in runs:
        for result in run.results:
            counts[result.status.value] += 1
    return counts


def _round(value: float | None, digits: int = 4) -> float | None:
    return None if value is None else round(float(value), digits)


DRIFT_WINDOW = 100
"""Frames at each end of a sequence compared for drift."""


def _drift(angles: np.ndarray, reference: np.ndarray) -> dict[str, float | None]:
    """Mean angle error over the first and the last ``DRIFT_WINDOW`` frames.

    Only for sequences of at least two windows; empty otherwise.
    """
    if len(reference) < 2 * DRIFT_WINDOW:
        return {}
    first = angle_errors(angles[:DRIFT_WINDOW], reference[:DRIFT_WINDOW])["mean"]
    last = angle_errors(angles[-DRIFT_WINDOW:], reference[-DRIFT_WINDOW:])["mean"]
    return {"first_100_deg": _round(first), "last_100_deg": _round(last)}


VIEWS: dict[str, tuple[float, float]] = {
    "front": (0.0, 60.0),
    "side": (60.0, 120.0),
    "back": (120.0, 180.01),
}
"""Bins of the reference's :func:`~posedrift.skeleton.facing_yaw` (degrees) for the
per-view errors: facing the camera, side on, back to the camera."""


def facing_by_view(joints: np.ndarray, reference: np.ndarray) -> dict[str, tuple]:
    """Median facing yaw of a skeleton and of the reference, per view (``VIEWS``).

    Says whether a method follows a person who turns: a skeleton that still faces
    the camera when the person's back is to it reads about 0 against 180.

    Parameters
    ----------
    joints, reference : (T, 15, 3) float
        The method's joints and the reference's, frame by frame (camera frame).

    Returns
    -------
    dict
        ``{view: (joints' median, reference's median)}`` in degrees, over the frames
        of that view (by the reference's yaw) where the joints' yaw is known;
        ``(None, None)`` where there is no such frame.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.skeleton import t_pose_joints
    >>> facing = t_pose_joints(1.75) * [1.0, -1.0, -1.0] + [0.0, 0.0, 3.0]  # camera frame
    >>> away = facing * [-1.0, 1.0, -1.0] + [0.0, 0.0, 6.0]  # turned about the vertical
    >>> views = facing_by_view(facing[None], away[None])  # a skeleton that did not turn
    >>> views["back"], views["front"]
    ((0.0, 180.0), (None, None))
    """
    yaw, est_yaw = facing_yaw(reference), facing_yaw(joints)
    out = {}
    for view, (low, high) in VIEWS.items():
        both = (yaw >= low) & (yaw < high) & np.isfinite(est_yaw)
        if both.any():
            out[view] = (float(np.median(est_yaw[both])), float(np.median(yaw[both])))
        else:
            out[view] = (None, None)
    return out


def _by_view(joints: np.ndarray, reference: np.ndarray, ref_angles: np.ndarray) -> dict:
    """Per view (``VIEWS``): frames, mean angle error and the median facing yaws."""
    yaw = facing_yaw(reference)
    angles = joint_angles(joints)
    facing = facing_by_view(joints, reference)
    out = {}
    for view, (low, high) in VIEWS.items():
        sel = (yaw >= low) & (yaw < high)
        mean = angle_errors(angles[sel], ref_angles[sel])["mean"] if sel.any() else None
        own, ref = facing[view]
        out[view] = {
            "frames": int(sel.sum()),
            "angle_error_mean_deg": _round(mean),
            "facing_yaw_median_deg": _round(own),
            "reference_facing_yaw_median_deg": _round(ref),
        }
    return out


def _reference_in_view(record: SequenceRecord) -> np.ndarray:
    """``(T, 8)``: the sequence's reference angles whose joints all lie in its frames."""
    return angles_in_view(record.reference.joints, record.intrinsics)


def _in_view(angles: np.ndarray, ref_angles: np.ndarray, in_view: np.ndarray) -> dict:
    """The angle errors split by whether the reference's joints lie in the image."""
    known = np.isfinite(ref_angles)
    share = float(in_view[known].mean()) if known.any() else None
    inside = angle_errors(np.where(in_view, angles, np.nan), ref_angles)["mean"]
    outside = angle_errors(np.where(in_view, np.nan, angles), ref_angles)["mean"]
    return {
        "angle_share": _round(share),
        "angle_error_mean_deg": _round(inside),
        "out_of_view_angle_error_mean_deg": _round(outside),
    }


def _seen(angles: np.ndarray, ref_angles: np.ndarray, seen: np.ndarray) -> dict:
    """The angle errors split by whether the frames show the reference's joints."""
    known = np.isfinite(ref_angles)
    share = float(seen[known].mean()) if known.any() else None
    errors = angle_errors(np.where(seen, angles, np.nan), ref_angles)
    hidden = angle_errors(np.where(seen, np.nan, angles), ref_angles)["mean"]
    return {
        "angle_share": _round(share),
        "angle_error_deg": {k: _round(v) for k, v in errors.items()},
        "hidden_angle_error_mean_deg": _round(hidden),
    }


def _sequence_summary(joints: np.ndarray, record: SequenceRecord) -> dict:
    """One method's errors on one sequence (the JSON's ``per_sequence`` entries)."""
    reference = record.reference
    angles = joint_angles(joints)
    out = {
        "angle_error_mean_deg": _round(angle_errors(angles, reference.angles)["mean"]),
        "mpjpe_mm": _round(mpjpe_mm(joints, reference.joints), 2),
        "failed_frames": int(np.count_nonzero(failed_frames(joints))),
        **_drift(angles, reference.angles),
    }
    if record.angles_seen is not None:
        seen = _seen(angles, reference.angles, record.angles_seen)
        out["seen_angle_share"] = seen["angle_share"]
        out["seen_angle_error_mean_deg"] = seen["angle_error_deg"]["mean"]
    return out


def summarize(run: EvaluationRun, *, convention: str = "native") -> dict:
    """The JSON of ``posedrift eval`` (``METHOD.md`` section 6) from a run.

    With ``convention`` other than ``"native"``, every method's joints are first
    moved to that skeleton convention (:func:`posedrift.skeleton.to_convention`, e.g.
    ``"kinect"`` against a Kinect SDK reference); the report then says so in
    ``"convention"``, and each method's ``"native"`` block keeps the errors of the
    unconverted joints.

    Errors are computed over all frames of all sequences together; failed frames
    (no pose) are counted and left out of the error means. Extra fields beyond
    section 6: per method ``"angle_agreement"`` (each angle's bias and 95% limits of
    agreement with the reference, :func:`~posedrift.evaluation.angle_agreement`),
    ``"filled"`` (the same errors with each failed frame
    filled by the last known pose), ``"per_sequence"``, ``"method_errors"``
    (exceptions a method raised, counted as failed frames) and ``"status_counts"``
    (frames per :class:`~posedrift.tracking.FrameStatus`), ``"by_view"`` (the mean
    angle error over the frames where the reference faces the camera, is side on,
    or has its back to it: :data:`VIEWS`; with the median facing yaw of the method's
    skeleton and of the reference there), ``"in_view"`` (the share of the
    reference's angles whose joints all lie in the image,
    :func:`~posedrift.evaluation.angles_in_view`, the mean angle error over them
    and over the rest: a joint outside the image leaves nothing to measure it
    by), ``"seen"`` (the share of the reference's angles whose joints the frames
    show, in the image and hidden by nothing, :func:`~posedrift.evaluation.angles_seen`;
    the angle errors over them, per angle and their mean, and the mean over the
    rest; where the run kept the frames' visibility); per sequence of at least 200 frames,
    ``"first_100_deg"`` and ``"last_100_deg"`` (drift).
    """
    out: dict[str, Any] = {
        "protocol": run.protocol,
        "convention": convention,
        "frames": int(sum(len(s.reference) for s in run.sequences)),
        "sequences": [s.name for s in run.sequences],
        "methods": {},
    }
    for name in run.methods:
        per = [run.runs[(name, s.name)] for s in run.sequences]
        native = [r.joints for r in per]
        converted = [to_convention(j, convention) for j in native]
        est = np.concatenate(converted)
        filled = np.concatenate([fill_forward(j) for j in converted])
        ref = np.concatenate([s.reference.joints for s in run.sequences])
        ref_angles = np.concatenate([s.reference.angles for s in run.sequences])
        in_view = np.concatenate([_reference_in_view(s) for s in run.sequences])
        seen = [s.angles_seen for s in run.sequences]
        hits = sum(r.label_hits for r in per)
        counted = sum(r.label_total for r in per)
        seconds = sum(r.seconds for r in per)
        est_angles = joint_angles(est)
        errors = angle_errors(est_angles, ref_angles)
        row = {
            "angle_error_deg": {k: _round(v) for k, v in errors.items()},
            "angle_agreement": {
                angle: {k: v if k == "frames" else _round(v) for k, v in values.items()}
                for angle, values in angle_agreement(est_angles, ref_angles).items()
            },
            "mpjpe_mm": _round(mpjpe_mm(est, ref), 2),
            "map_10cm": _round(map_at(est, ref, 0.10)),
            "label_accuracy": _round(hits / counted) if counted else None,
            "frames_per_second": _round(len(est) / seconds, 2) if seconds > 0 else None,
            "failed_frames": int(np.count_nonzero(failed_frames(est))),
            "filled": {
                "angle_error_deg": {
                    k: _round(v) for k, v in angle_errors(joint_angles(filled), ref_angles).items()
                },
                "mpjpe_mm": _round(mpjpe_mm(filled, ref), 2),
                "map_10cm": _round(map_at(filled, ref, 0.10)),
            },
            "per_sequence": {
                s.name: _sequence_summary(j, s)
                for s, j in zip(run.sequences, converted, strict=True)
            },
            "method_errors": sum(len(r.errors) for r in per),
            "status_counts": _status_counts(per),
            "by_view": _by_view(est, ref, ref_angles),
            "in_view": _in_view(est_angles, ref_angles, in_view),
        }
        if all(s is not None for s in seen):
            row["seen"] = _seen(est_angles, ref_angles, np.concatenate(seen))
        if convention != "native":
            raw = np.concatenate(native)
            row["native"] = {
                "angle_error_mean_deg": _round(angle_errors(joint_angles(raw), ref_angles)["mean"]),
                "mpjpe_mm": _round(mpjpe_mm(raw, ref), 2),
                "map_10cm": _round(map_at(raw, ref, 0.10)),
            }
        out["methods"][name] = row
    return out


def evaluate(
    sequences: Iterable[EvaluationSequence],
    methods: Sequence[str] | Mapping[str, MethodFactory] = DEFAULT_METHODS,
    *,
    forest: Any = None,
    part_net: Any = None,
    progress: bool = True,
    figures_dir: str | Path | None = None,
    protocol: str | None = None,
    convention: str = "native",
    on_skip: Callable[[str, str], None] | None = None,
    repeats: int = 1,
    smooth: float = 0.0,
    smooth_lag: float | None = None,
) -> dict:
    """Evaluate methods on sequences: the JSON of ``posedrift eval`` (``METHOD.md`` section 6).

    Parameters
    ----------
    sequences : iterable of EvaluationSequence
    methods : sequence of str, or mapping of name -> factory
        Default ``("cpd", "shotton", "pda", "icp")``; see :data:`METHODS`.
    forest : BodyPartForest, optional
        Shared by all methods (the default model, loaded once, when None).
    part_net : BodyPartNet, FacingNets or "none", optional
        Shared by the methods that label pixels with it (see :func:`run_methods`).
    progress : bool
        Progress bar on standard error.
    figures_dir : path, optional
        Write the figures (Fig. 9, 6, 12 of the paper, and a Bland-Altman plot) there
        as PNG files.
    protocol : str, optional
        ``"synthetic"`` or ``"utd"`` (inferred by default).
    convention : str
        Skeleton convention of the reference (:data:`posedrift.skeleton.CONVENTIONS`):
        the methods' joints are converted to it before scoring (see :func:`summarize`).
    on_skip : callable, optional
        ``on_skip(name, reason)`` for each sequence that cannot be evaluated (see
        :func:`run_methods`); by default a ``RuntimeWarning``.
    repeats : int
        Run the methods that sample points at random (the trackers) this many
        times, with seeds ``0 .. repeats - 1``: a tracker's errors vary from one
        point sample to the next (each frame starts from the last one's result), and
        comparisons need that spread. Their numbers are then the means over the runs,
        with a ``"repeats"`` block (see :func:`mean_of_repeats`), and the report says
        ``"repeats": n``; the other methods and the figures come from the first run.
    smooth : float
        Seconds: score every method's joints smoothed offline, without lag (see
        :func:`run_methods`); the report then says ``"smoothing_s": smooth``.
    smooth_lag : float, optional
        With ``smooth``: the latest frame used after each one, seconds (see
        :func:`run_methods`); the report then says ``"smoothing_lag_s"``.

    Returns
    -------
    dict
        ``{"protocol", "frames", "sequences", "methods": {name: {"angle_error_deg",
        "mpjpe_mm", "map_10cm", "label_accuracy", "frames_per_second",
        "failed_frames", ...}}}`` (see :func:`summarize`).
    """
    if convention not in CONVENTIONS:
        raise ValueError(
            f"Unknown joint convention {convention!r}: expected one of {sorted(CONVENTIONS)}."
        )
    repeats = int(
        check_scalar(repeats, "repeats", low=1, include_low=True, integer=True, caller="evaluate")
    )
    if repeats > 1 and not isinstance(sequences, Sequence):
        sequences = list(sequences)  # walked once per repeat
    run = run_methods(
        sequences,
        methods,
        forest=forest,
        part_net=part_net,
        progress=progress,
        protocol=protocol,
        keep_frames=figures_dir is not None,
        on_skip=on_skip,
        smooth=smooth,
        smooth_lag=smooth_lag,
    )
    report = summarize(run, convention=convention)
    if smooth:
        report["smoothing_s"] = smooth
        if smooth_lag is not None:
            report["smoothing_lag_s"] = smooth_lag
    seeded = {name: f for name, f in _factories(methods).items() if _is_seeded(f)}
    if repeats > 1 and seeded:
        rows = {name: [report["methods"][name]] for name in seeded}
        for seed in range(1, repeats):
            again = run_methods(
                sequences,
                seeded,
                forest=run.forest,
                part_net=part_net,
                progress=progress,
                protocol=run.protocol,
                on_skip=lambda name, reason: None,  # reported by the first run
                seed=seed,
                smooth=smooth,
                smooth_lag=smooth_lag,
            )
            for name, row in summarize(again, convention=convention)["methods"].items():
                rows[name].append(row)
        for name, runs in rows.items():
            report["methods"][name] = mean_of_repeats(runs)
        report["repeats"] = repeats
    if figures_dir is not None:
        from posedrift.evaluation._figures import write_figures

        written = write_figures(run, figures_dir, forest=run.forest, convention=convention)
        report["figures"] = [str(p) for p in written]
    return report


__all__ = [
    "DEFAULT_METHODS",
    "METHODS",
    "VIEWS",
    "EvaluationRun",
    "MethodRun",
    "SequenceRecord",
    "evaluate",
    "facing_by_view",
    "label_hits",
    "make_method",
    "mean_of_repeats",
    "parse_methods",
    "run_methods",
    "summarize",
    "unusable_reason",
]
