"""``posedrift track``: poses from a depth recording."""

from __future__ import annotations

import time
from collections import Counter
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from posedrift.cli._app import app, fail, progress_enabled
from posedrift.cli._options import (
    CameraOption,
    DepthInput,
    DepthScaleOption,
    FpsOption,
    IntrinsicsOption,
    SmoothLagOption,
    SmoothOption,
    UnmirrorOption,
    check_smoothing,
    depth_scale_hint,
)

EXIT_UNREADABLE_FRAMES = 1
EXIT_INTERRUPTED = 130
"""128 + SIGINT, as shells report a run stopped by Ctrl-C."""


@app.command("track")
def track(
    source: DepthInput,
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    camera: CameraOption = None,
    intrinsics: IntrinsicsOption = None,
    depth_scale: DepthScaleOption = None,
    fps: FpsOption = 30.0,
    n_points: Annotated[
        int, typer.Option("--points", min=20, help="Points per frame after downsampling.")
    ] = 400,
    unmirror: UnmirrorOption = None,
    smooth: SmoothOption = 0.0,
    smooth_lag: SmoothLagOption = None,
    decimation: Annotated[
        int | None,
        typer.Option(
            "--decimation",
            min=1,
            help="Work on every N-th pixel of every N-th row (default: 2 for 640 x 480 "
            "cameras, 1 at 320 x 240; 1 keeps every pixel).",
        ),
    ] = None,
    height: Annotated[
        float | None,
        typer.Option(
            "--height",
            help="The person's stature in metres, in [0.5, 2.6], if known (default: measured "
            "on the first frame with a person).",
        ),
    ] = None,
    video: Annotated[bool, typer.Option("--video/--no-video", help="Write tracking.gif.")] = True,
    viewer: Annotated[
        bool, typer.Option("--viewer/--no-viewer", help="Write the HTML 3-D viewer.")
    ] = True,
    point_clouds: Annotated[
        str | None,
        typer.Option("--point-clouds", help="Also write labelled points per frame: npz or ply."),
    ] = None,
    convention: Annotated[
        str,
        typer.Option(
            "--convention",
            help="Joints as recovered (native) or moved to where the Kinect v1 SDK puts them "
            "(kinect; fixed offsets fitted on UTD-MHAD).",
        ),
    ] = "native",
) -> None:
    """Recover the pose in every frame of a depth recording.

    Writes OUT/poses.json, poses.csv, poses.bvh, angles.png, tracking.gif and
    viewer.html. With --convention kinect, every output holds the joints moved to
    the Kinect SDK's skeleton convention (posedrift.skeleton.to_convention), for
    comparison with Kinect-based tools. With --smooth S, every output holds the
    joints smoothed over the whole recording (S seconds, without lag;
    posedrift.tracking.smooth_results), with --smooth-lag L as a live stream with L
    seconds of latency would have them. Exit status 1 when a frame could not be
    read (the others are still processed and written), 2 for unusable input or
    options (an unusable --out is reported before any work), 130 after Ctrl-C
    (the outputs then hold the frames processed so far). Frames without a person
    are a per-frame status (no_person), not an error: exit status 0, and the
    summary says when no frame had one.

    Example: posedrift track recording/ --out poses/ --camera kinect1-vga
    """
    from rich.progress import Progress

    from posedrift.cli._outputs import check_output_dir, video_stride, write_outputs
    from posedrift.io import UnreadableFrame, open_depth_source
    from posedrift.skeleton import CONVENTIONS
    from posedrift.tracking import FrameResult, FrameStatus, PoseTracker, smooth_results

    if point_clouds not in (None, "npz", "ply"):
        raise fail(f"--point-clouds must be 'npz' or 'ply'. Got {point_clouds!r}.")
    if convention not in CONVENTIONS:
        raise fail(
            f"Unknown --convention {convention!r}: expected one of {', '.join(CONVENTIONS)}."
        )
    if height is not None and not 0.5 <= height <= 2.6:
        raise fail(f"--height must be in [0.5, 2.6] metres. Got {height:g}.")
    check_smoothing(smooth, smooth_lag)
    check_output_dir(out, "--out")
    if point_clouds:
        check_output_dir(out / "points", "--point-clouds")
    try:
        reader = open_depth_source(
            source,
            camera=camera,
            intrinsics=intrinsics,
            depth_scale=depth_scale,
            fps=fps,
            unmirror=unmirror,
        )
    except (OSError, ValueError) as exc:
        raise fail(str(exc)) from exc
    tracker = PoseTracker(
        reader.intrinsics, n_points=n_points, decimation=decimation, height=height
    ).load_models()  # before the clock starts: the rate is the frames'
    results: list[FrameResult] = []
    frames: list = []
    unreadable = 0
    with_depth = 0  # frames with at least one valid (positive, finite) depth pixel
    first_depth = np.nan  # median depth of the first of them (metres, as read)
    seconds = 0.0
    written: dict = {}
    interrupted = False
    stride = video_stride(len(reader))  # only the frames the animation shows are kept
    try:
        with Progress(disable=not progress_enabled(), transient=True) as bar:
            task = bar.add_task(f"tracking {source.name}", total=len(reader))
            for item in reader:
                if isinstance(item, UnreadableFrame):
                    unreadable += 1
                    message = f"{item.source}: {item.message}"
                    typer.echo(f"warning: {message}", err=True)
                    results.append(FrameResult.empty(item.index, FrameStatus.LOST, message))
                    frames.append(None)
                else:
                    has_depth = bool(np.any(item.depth > 0))
                    if has_depth and not with_depth:
                        first_depth = float(np.median(item.depth[item.depth > 0]))
                    with_depth += has_depth
                    start = time.perf_counter()
                    results.append(tracker.process(item))
                    seconds += time.perf_counter() - start
                    keep = video and len(frames) % stride == 0
                    frames.append(item if keep else None)
                bar.advance(task)
    except KeyboardInterrupt:
        interrupted = True
    finally:  # whatever was processed is written, even after an interruption
        if results:
            results = smooth_results(results, smooth, lag=smooth_lag, fps=reader.fps)
            results = _in_convention(results, convention)
            written = write_outputs(
                results,
                frames,
                out,
                intrinsics=reader.intrinsics,
                fps=reader.fps,
                video=video,
                viewer=viewer,
                stride=stride,
                joint_convention=convention,
                smoothing={"sigma_s": smooth, "lag_s": smooth_lag} if smooth else None,
            )
            if point_clouds:
                from posedrift.io import write_point_clouds

                written["points"] = write_point_clouds(results, out / "points", fmt=point_clouds)
    _summary(results, seconds, written)
    if results and not interrupted:
        _no_pose_warning(
            results,
            unreadable=unreadable,
            with_depth=with_depth,
            source=source,
            first_depth=first_depth,
        )
    if interrupted:
        n = len(results)
        typer.echo(
            f"interrupted at frame {n} of {len(reader)}: "
            + (
                f"the outputs in {out} hold the {n} frames processed so far (0 to {n - 1})."
                if n
                else "no frame was processed, nothing written."
            ),
            err=True,
        )
        raise typer.Exit(EXIT_INTERRUPTED)
    if unreadable:
        raise typer.Exit(EXIT_UNREADABLE_FRAMES)


def _no_pose_warning(
    results: list, *, unreadable: int, with_depth: int, source: Path, first_depth: float
) -> None:
    """Say plainly when no frame of the input gave a pose, and the likely reason."""
    from posedrift.tracking import FrameStatus

    if any(r.status in (FrameStatus.TRACKED, FrameStatus.REINITIALIZED) for r in results):
        return
    n = len(results)
    if unreadable == n:
        reason = f"none of the {n} frames of {source} could be read"
    elif with_depth == 0:
        reason = (
            f"no frame of {source} has valid depth (every pixel is 0, NaN or negative); "
            f"check the input and --depth-scale"
        )
    else:
        reason = f"no person was found (or posed) in any of the {n} frames of {source}"
        if hint := depth_scale_hint(first_depth):
            reason += f"; its {hint}"
    typer.echo(f"warning: no pose recovered: {reason}.", err=True)


def _in_convention(results: list, convention: str) -> list:
    """The results with their joints moved to ``convention`` (unchanged for native)."""
    if convention == "native":
        return results
    from dataclasses import replace

    from posedrift.skeleton import to_convention

    return [replace(r, joints=to_convention(r.joints, convention)) for r in results]


def _summary(results, seconds: float, written: dict) -> None:
    counts = Counter(r.status.value for r in results)
    processed = sum(1 for r in results if r.timings_ms)
    rate = processed / seconds if seconds > 0 else float("nan")
    typer.echo(
        f"{len(results)} frames: "
        + ", ".join(f"{n} {status}" for status, n in sorted(counts.items()))
        + f"; {rate:.0f} frames per second (reading and loading the models excluded)"
    )
    stages: dict[str, list[float]] = {}
    for r in results:
        for stage, ms in r.timings_ms.items():
            stages.setdefault(stage, []).append(ms)
    if stages:
        typer.echo(
            "median ms per stage: "
            + ", ".join(f"{k} {np.median(v):.2f}" for k, v in stages.items())
        )
    for name, path in written.items():
        if isinstance(path, list | tuple):  # one file per frame: say where and how many
            folder = path[0].parent if path else "-"
            typer.echo(f"{name}: {len(path)} files in {folder}")
        else:
            typer.echo(f"{name}: {path}")
