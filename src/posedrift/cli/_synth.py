"""``posedrift synth``: render a motion clip into a synthetic depth folder."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import app, fail, progress_enabled


def _parse_size(text: str) -> tuple[int, int]:
    parts = text.lower().replace(" ", "").split("x")
    try:
        width, height = (int(p) for p in parts)
    except ValueError:
        raise ValueError(f"--size must be WIDTHxHEIGHT, e.g. 320x240. Got {text!r}.") from None
    if width <= 0 or height <= 0:
        raise ValueError(f"--size must be positive, e.g. 320x240. Got {text!r}.")
    return width, height


@app.command("synth")
def synth(
    source: Annotated[
        str, typer.Argument(help="A BVH motion file, or 'builtin' for the procedural clip.")
    ],
    out: Annotated[Path, typer.Option("--out", "-o", help="Output folder.")],
    frames: Annotated[
        int | None,
        typer.Option(
            "--frames",
            "-n",
            min=1,
            help="Frames to write from the T-pose on (default: the whole clip).",
        ),
    ] = None,
    camera: Annotated[
        str | None,
        typer.Option("--camera", help="Camera preset (kinect1-qvga, kinect1-vga, kinect2, d435)."),
    ] = None,
    intrinsics: Annotated[
        str | None,
        typer.Option("--intrinsics", help="fx,fy,cx,cy in pixels (with --size)."),
    ] = None,
    size: Annotated[
        str, typer.Option("--size", help="Image size WIDTHxHEIGHT for --intrinsics.")
    ] = "320x240",
    distance: Annotated[
        float, typer.Option("--distance", help="Camera to person at frame 0, metres.")
    ] = 2.8,
    camera_height: Annotated[
        float, typer.Option("--camera-height", help="Camera height above the floor, metres.")
    ] = 1.0,
    noise: Annotated[
        bool, typer.Option("--noise/--no-noise", help="Kinect v1-like depth noise.")
    ] = False,
    in_place: Annotated[
        bool,
        typer.Option(
            "--in-place/--world-motion",
            help="Remove the walking travel so the person stays in view (angles unchanged).",
        ),
    ] = False,
    background: Annotated[
        bool, typer.Option("--background/--no-background", help="Render a floor and back wall.")
    ] = False,
    height: Annotated[
        float | None,
        typer.Option("--height", help="Person's stature in metres (default: the clip's own)."),
    ] = None,
    girth: Annotated[float, typer.Option("--girth", help="Body girth factor (1 = default).")] = 1.0,
    fps: Annotated[float, typer.Option("--fps", help="Frame rate to resample to.")] = 30.0,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the noise.")] = 0,
    sheet: Annotated[
        Path | None,
        typer.Option("--sheet", help="Contact sheet PNG (default: DIR/contact_sheet.png)."),
    ] = None,
) -> None:
    """Render SOURCE into DIR/depth (uint16 mm PNG), DIR/labels (part + 1) and ground truth.

    DIR/ground_truth.json holds the intrinsics, fps, the 15 joints (metres, camera
    frame) and the eight angles of every frame. Frame 0 is the T-pose calibration
    frame; without --frames the whole clip is written at 30 fps. A contact sheet
    (depth beside labels, a few frames) is written for a person to look at.

    Example: posedrift synth builtin --out walk --frames 90 --noise --background
    """
    from posedrift.camera import camera_preset, parse_intrinsics
    from posedrift.synthetic import build_sequence, contact_sheet, write_synthetic

    # --- camera -----------------------------------------------------------------------
    try:
        if camera is not None and intrinsics is not None:
            raise ValueError("Give either --camera or --intrinsics, not both.")
        if intrinsics is not None:
            width, height_px = _parse_size(size)
            k = parse_intrinsics(intrinsics, width=width, height=height_px)
        else:
            k = camera_preset(camera or "kinect1-qvga")
    except ValueError as exc:
        raise fail(str(exc)) from exc

    # --- motion -----------------------------------------------------------------------
    try:
        motion = _load_source(source)
    except ValueError as exc:
        raise fail(str(exc)) from exc

    shape = {"girth": girth} if girth != 1.0 else None

    show = progress_enabled()
    try:
        with _Progress(show, f"rendering {motion.name or source}") as on_frame:
            sequence = build_sequence(
                motion,
                intrinsics=k,
                distance=distance,
                camera_height=camera_height,
                n_frames=frames,
                fps=fps,
                noise=noise,
                background=background,
                shape=shape,
                stature=height,
                in_place=in_place,
                rng=seed,
                on_frame=on_frame,
            )
        paths = write_synthetic(sequence, out, progress=show)
        sheet_path = contact_sheet(sequence, sheet or out / "contact_sheet.png")
    except ValueError as exc:
        raise fail(str(exc)) from exc
    n = len(sequence.frames)
    typer.echo(
        f"wrote {n} frames ({n / sequence.fps:.1f} s at {sequence.fps:g} fps, "
        f"{k.width}x{k.height}) of {sequence.name} -> {out} "
        f"({paths['ground_truth'].name}, contact sheet {sheet_path})"
    )


def _load_source(source: str):
    """``builtin`` or a BVH file, as a Motion; errors name the file."""
    from posedrift.synthetic import bvh_motion, procedural_motion

    if source == "builtin":
        return procedural_motion(fps=30.0)
    path = Path(source)
    if not path.is_file():
        raise ValueError(
            f"SOURCE {source!r} is neither 'builtin' nor a readable BVH file "
            f"({'no such file' if not path.exists() else 'not a file'})."
        )
    try:
        return bvh_motion(path)
    except (ValueError, OSError, UnicodeDecodeError) as exc:
        message = str(exc)
        if str(path) not in message and path.name not in message:
            message = f"{path}: {message}"
        raise ValueError(f"SOURCE is not a readable BVH file: {message}") from exc


class _Progress:
    """A rich progress bar driven by ``on_frame(done, total)``, or nothing."""

    def __init__(self, enabled: bool, description: str) -> None:
        self.enabled = enabled
        self.description = description
        self._bar = None
        self._task = None

    def __enter__(self):
        if not self.enabled:
            return None
        from rich.console import Console
        from rich.progress import Progress

        self._bar = Progress(console=Console(stderr=True), transient=True)
        self._bar.start()
        self._task = self._bar.add_task(self.description, total=None)

        def on_frame(done: int, total: int) -> None:
            self._bar.update(self._task, completed=done, total=total)

        return on_frame

    def __exit__(self, *exc) -> None:
        if self._bar is not None:
            self._bar.stop()
