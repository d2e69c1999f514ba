"""``posedrift synth``: render a motion clip into a synthetic depth folder."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import app, fail, progress_enabled
from posedrift.cli._options import CameraTiltOption


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
        str | None,
        typer.Option(
            "--size",
            help="Image size WIDTHxHEIGHT of --intrinsics (default 320x240); a --camera "
            "preset has its own size.",
        ),
    ] = None,
    distance: Annotated[
        float,
        typer.Option("--distance", help="Camera to person at frame 0, metres."),
    ] = 2.8,
    camera_height: Annotated[
        float, typer.Option("--camera-height", help="Camera height above the floor, metres.")
    ] = 1.0,
    camera_tilt: CameraTiltOption = 0.0,
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
    facing: Annotated[
        float,
        typer.Option(
            "--facing",
            help="Degrees the person is turned from the camera at frame 0, to their left "
            "(90 shows the right side, 180 the back; 0 faces the camera).",
        ),
    ] = 0.0,
    height: Annotated[
        float | None,
        typer.Option(
            "--height",
            help="Person's stature in metres, in (0.5, 2.5) (default: the clip's own).",
        ),
    ] = None,
    girth: Annotated[
        float,
        typer.Option("--girth", help="Body girth factor, > 0 (1 = default)."),
    ] = 1.0,
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
    (depth beside labels, a few frames) is written for a person to look at. Frames
    where the person is out of view are counted in a warning; when no frame shows
    the person, nothing is written and the exit status is 1.

    Example: posedrift synth builtin --out walk --frames 90 --noise --background
    """
    from posedrift.cli._outputs import check_output_dir, check_output_file
    from posedrift.synthetic import build_sequence, contact_sheet, write_synthetic

    for option, value, low, high in (
        ("--height", height, 0.5, 2.5),
        ("--girth", girth, 0.0, None),
        ("--distance", distance, 0.0, None),
        ("--fps", fps, 0.0, None),
        ("--facing", facing, -360.0, 360.0),
        ("--camera-tilt", camera_tilt, -90.0, 90.0),
    ):
        _check_range(option, value, low, high)
    check_output_dir(out, "--out")
    if sheet is not None:
        check_output_file(sheet, "--sheet")
    try:
        k = _camera(camera, intrinsics, size)
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
                camera_tilt=camera_tilt,
                n_frames=frames,
                fps=fps,
                noise=noise,
                background=background,
                shape=shape,
                stature=height,
                in_place=in_place,
                facing=facing,
                rng=seed,
                on_frame=on_frame,
            )
        empty = [i for i, labels in enumerate(sequence.reference.labels) if not labels.any()]
        if len(empty) == len(sequence.frames):
            raise fail(
                f"no frame shows the person: they are out of the {k.width}x{k.height} view "
                f"(--camera-height {camera_height:g} m, --camera-tilt {camera_tilt:g}, "
                f"--distance {distance:g} m). "
                "Nothing written.",
                code=1,
            )
        paths = write_synthetic(sequence, out, progress=show)
        sheet_path = contact_sheet(sequence, sheet or out / "contact_sheet.png")
    except ValueError as exc:
        raise fail(str(exc)) from exc
    if empty:
        shown = ", ".join(str(i) for i in empty[:10]) + (" ..." if len(empty) > 10 else "")
        typer.echo(
            f"warning: {len(empty)} of {len(sequence.frames)} frames show no person "
            f"(out of view): frames {shown}.",
            err=True,
        )
    n = len(sequence.frames)
    typer.echo(
        f"wrote {n} frames ({n / sequence.fps:.1f} s at {sequence.fps:g} fps, "
        f"{k.width}x{k.height}) of {sequence.name} -> {out} "
        f"({paths['ground_truth'].name}, contact sheet {sheet_path})"
    )


_RIG_HINT = re.compile(r"Pass rig=.*$", re.DOTALL)
_RIG_ADVICE = (
    "Rename the file's joints to the names looked for, or map them in Python: "
    "posedrift.synthetic.bvh_motion(path, rig={joint name: node name})."
)


def _check_range(option: str, value: float | None, low: float, high: float | None) -> None:
    """Fail naming ``option`` unless ``value`` (None: not given) lies in ``(low, high)``."""
    if value is None or (low < value and (high is None or value < high)):
        return  # NaN fails both comparisons, so it is rejected too
    interval = f"in ({low:g}, {high:g})" if high is not None else f"greater than {low:g}"
    raise fail(f"{option} must be {interval}. Got {value:g}.")


def _camera(camera: str | None, intrinsics: str | None, size: str | None):
    """The Intrinsics that --camera, --intrinsics and --size ask for."""
    from posedrift.camera import CAMERA_PRESETS, camera_preset, parse_intrinsics

    if camera is not None and intrinsics is not None:
        raise ValueError("Give either --camera or --intrinsics, not both.")
    if intrinsics is not None:
        width, height = _parse_size(size or "320x240")
        return parse_intrinsics(intrinsics, width=width, height=height)
    name = camera or "kinect1-qvga"
    k = camera_preset(name)
    if size is not None and _parse_size(size) != (k.width, k.height):
        width, height = _parse_size(size)
        same = [n for n, p in CAMERA_PRESETS.items() if (p.width, p.height) == (width, height)]
        others = f" (or {', '.join(same[1:])})" if len(same) > 1 else ""
        presets = f"--camera {same[0]}{others}, or " if same else ""
        raise ValueError(
            f"--size {size} goes with --intrinsics: the camera preset {name!r} is "
            f"{k.width}x{k.height}. For {width}x{height} frames, give "
            f"{presets}--intrinsics fx,fy,cx,cy with --size {width}x{height}."
        )
    return k


def _load_source(source: str):
    """``builtin`` or a BVH file, as a Motion.

    Raises
    ------
    ValueError
        With a message that starts with the file's name (and names it only there):
        no such file, not a file, malformed BVH, or joints that cannot be mapped
        (with what to do about it on the command line).
    """
    from posedrift.synthetic import bvh_motion, procedural_motion

    if source == "builtin":
        return procedural_motion(fps=30.0)
    path = Path(source)
    if not path.is_file():
        why = "no such file" if not path.exists() else "not a file"
        raise ValueError(f"{source}: {why} (SOURCE is a BVH file or 'builtin').")
    try:
        return bvh_motion(path)
    except OSError as exc:
        raise ValueError(f"{source}: cannot read the file ({exc.strerror or exc}).") from exc
    except UnicodeDecodeError as exc:
        raise ValueError(f"{source}: not a BVH file (not text: {exc.reason}).") from exc
    except ValueError as exc:
        message = _RIG_HINT.sub(_RIG_ADVICE, str(exc))
        if not message.startswith(str(path)):
            message = f"{source}: {message}"
        raise ValueError(message) from exc


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
