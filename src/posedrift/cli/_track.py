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
    UnmirrorOption,
)

EXIT_UNREADABLE_FRAMES = 1


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
    comparison with Kinect-based tools. Exit status 1 when a frame could not be
    read (the others are still processed and written), 2 for unusable input or
    options.

    Example: posedrift track recording/ --out poses/ --camera kinect1-vga
    """
    from rich.progress import Progress

    from posedrift.cli._outputs import video_stride, write_outputs
    from posedrift.io import UnreadableFrame, open_depth_source
    from posedrift.skeleton import CONVENTIONS
    from posedrift.tracking import FrameResult, FrameStatus, PoseTracker

    if point_clouds not in (None, "npz", "ply"):
        raise fail(f"--point-clouds must be 'npz' or 'ply'. Got {point_clouds!r}.")
    if convention not in CONVENTIONS:
        raise fail(
            f"Unknown --convention {convention!r}: expected one of {', '.join(CONVENTIONS)}."
        )
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
    tracker = PoseTracker(reader.intrinsics, n_points=n_points)
    results: list[FrameResult] = []
    frames: list = []
    unreadable = 0
    seconds = 0.0
    written: dict = {}
    stride = video_stride(len(reader))  # only the frames the animation shows are kept
    try:
        with Progress(disable=not progress_enabled(), transient=True) as bar:
            task = bar.add_task(f"tracking {source.name}", total=len(reader))
            for item in reader:
                if isinstance(item, UnreadableFrame):
                    unreadable += 1
                    typer.echo(f"warning: {item.source}: {item.message}", err=True)
                    results.append(FrameResult.empty(item.index, FrameStatus.LOST, item.message))
                    frames.append(None)
                else:
                    start = time.perf_counter()
                    results.append(tracker.process(item))
                    seconds += time.perf_counter() - start
                    keep = video and len(frames) % stride == 0
                    frames.append(item if keep else None)
                bar.advance(task)
    finally:  # whatever was processed is written, even after an interruption
        if results:
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
            )
            if point_clouds:
                from posedrift.io import write_point_clouds

                written["points"] = write_point_clouds(results, out / "points", fmt=point_clouds)
    _summary(results, seconds, written)
    if unreadable:
        raise typer.Exit(EXIT_UNREADABLE_FRAMES)


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
        + f"; {rate:.0f} frames per second (reading excluded)"
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
        typer.echo(f"{name}: {path}")
