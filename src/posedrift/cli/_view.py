"""``posedrift view``: check a depth input before tracking it, and preview it as a GIF."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import app, fail, progress_enabled
from posedrift.cli._options import (
    CameraOption,
    DepthInput,
    DepthScaleOption,
    FpsOption,
    IntrinsicsOption,
    UnmirrorOption,
    depth_scale_hint,
)

EXIT_OK = 0
EXIT_UNREADABLE_FRAMES = 1
EXIT_BAD_INPUT = 2
PREVIEW_SUFFIXES = (".gif", ".mp4")


@app.command("view")
def view(
    source: DepthInput,
    out: Annotated[
        Path | None,
        typer.Option("--out", "-o", help="Write a depth preview animation here (.gif or .mp4)."),
    ] = None,
    camera: CameraOption = None,
    intrinsics: IntrinsicsOption = None,
    depth_scale: DepthScaleOption = None,
    fps: FpsOption = 30.0,
    unmirror: UnmirrorOption = None,
    strict: Annotated[
        bool,
        typer.Option("--strict", help="Exit with status 1 when any frame is unreadable."),
    ] = False,
) -> None:
    """Check a depth input: read every frame, report camera and depth range.

    Unreadable frames are listed with their file and reason.
    Exit status: 0 when the input is usable; 2 when it cannot be
    opened or used (the message says why and lists the valid choices;
    an input where no frame has valid depth is not usable; a bad --out
    is reported before any frame is read); 1 with --strict when some
    frames are unreadable.

    Example: posedrift view recording/ --camera kinect1-vga --out preview.gif
    """
    import numpy as np

    from posedrift.camera import DepthFrame
    from posedrift.cli._outputs import check_output_file
    from posedrift.io import UnreadableFrame, open_depth_source

    if out is not None:
        check_output_file(out, "--out", suffixes=PREVIEW_SUFFIXES)
        if out.suffix.lower() == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
            raise fail(
                f"--out {str(out)!r}: writing .mp4 needs imageio-ffmpeg "
                f"(pip install imageio-ffmpeg); or write a .gif instead.",
                EXIT_BAD_INPUT,
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
        total = len(reader)
    except (FileNotFoundError, ValueError, ImportError) as exc:
        raise fail(str(exc), EXIT_BAD_INPUT) from None
    frames: list = []
    bad: list[UnreadableFrame] = []
    nearest, farthest, coverage = np.inf, 0.0, []
    iterator = iter(reader)
    if progress_enabled():
        from rich.progress import track

        iterator = track(iterator, total=total, description="Reading", transient=True)
    try:
        for frame in iterator:
            if isinstance(frame, UnreadableFrame):
                bad.append(frame)
            elif isinstance(frame, DepthFrame):
                valid = frame.depth[frame.depth > 0]
                coverage.append(valid.size / frame.depth.size)
                if valid.size:
                    nearest = min(nearest, float(valid.min()))
                    farthest = max(farthest, float(valid.max()))
            if out is not None:
                frames.append(frame)
    except (ValueError, RuntimeError) as exc:
        raise fail(f"{source}: {exc}", EXIT_BAD_INPUT) from None
    k = reader.intrinsics
    typer.echo(f"input      {reader.path} ({type(reader).__name__})")
    typer.echo(f"frames     {total} ({total - len(bad)} readable, {len(bad)} unreadable)")
    typer.echo(
        f"camera     {k.width} x {k.height}, fx {k.fx:g}, fy {k.fy:g}, cx {k.cx:g}, cy {k.cy:g}"
    )
    if reader.depth_scale == 1.0:
        typer.echo("depth      in metres (1 unit per metre)")
    else:
        typer.echo(f"depth      {reader.depth_scale:g} units per metre")
    if reader.unmirror:
        typer.echo("mirrored   yes: frames flipped left-right, cx adjusted")
    if np.isfinite(nearest):
        typer.echo(
            f"range      {nearest:.3f} - {farthest:.3f} m; "
            f"{100 * float(np.mean(coverage)):.1f}% of pixels have depth"
        )
    elif coverage:
        typer.echo("range      none: no pixel of any frame has depth")
    if hint := depth_scale_hint(nearest):
        typer.echo(f"warning: {hint}.", err=True)
    for frame in bad[:20]:
        typer.echo(f"unreadable {frame}", err=True)
    if len(bad) > 20:
        typer.echo(f"unreadable ... and {len(bad) - 20} more", err=True)
    if not np.isfinite(nearest):
        what = (
            f"none of the {total} frames can be read"
            if not coverage
            else f"no frame has valid depth (every pixel of the {len(coverage)} readable "
            f"frames is 0, NaN or negative); check the input and --depth-scale"
        )
        raise fail(f"{source} is not usable: {what}.", EXIT_BAD_INPUT)
    if out is not None:
        from posedrift.visualization._draw import write_depth_video

        try:
            write_depth_video(frames, out, intrinsics=k, fps=min(fps, 30.0))
        except ValueError as exc:
            raise fail(str(exc), EXIT_BAD_INPUT) from None
        typer.echo(f"preview    {out}")
    if strict and bad:
        raise typer.Exit(EXIT_UNREADABLE_FRAMES)
