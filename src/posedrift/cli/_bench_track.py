"""``posedrift bench track``: the tracker's time per stage and frames per second, one core."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import bench_app, fail, progress_enabled
from posedrift.cli._options import CameraOption, NetOption, TurnedNetOption, load_part_net


@bench_app.command("track")
def bench_track_command(
    bvh: Annotated[
        list[Path] | None,
        typer.Argument(help="BVH clips to render and track (default: the built-in motion)."),
    ] = None,
    frames: Annotated[
        int, typer.Option("--frames", min=1, help="Frames rendered per sequence.")
    ] = 150,
    points: Annotated[
        int, typer.Option("--points", min=20, help="The tracker's points per frame.")
    ] = 400,
    repeats: Annotated[
        int, typer.Option("--repeats", min=1, help="Runs over the sequences (medians).")
    ] = 3,
    camera: CameraOption = None,
    distance: Annotated[
        float | None,
        typer.Option("--distance", min=0.3, help="The person's distance, metres (default 2.8)."),
    ] = None,
    room: Annotated[
        bool,
        typer.Option(
            "--room/--person-only",
            help="Render the floor and a wall behind the person, with Kinect-like noise.",
        ),
    ] = False,
    stage_clock: Annotated[
        str, typer.Option("--stage-clock", help="Clock of the stage timings: cpu or wall.")
    ] = "cpu",
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write the result as JSON here.")
    ] = None,
    net: NetOption = None,
    turned_net: TurnedNetOption = None,
) -> None:
    """Time the tracker per stage on a rendered synthetic sequence, on one thread.

    Renders the sequence first (not timed; with --camera, as that camera sees it),
    then runs PoseTracker over it --repeats times. Prints a Markdown table of the
    median milliseconds of each stage for tracked and re-initialized frames, the CPU
    milliseconds per frame and the frames per second (CPU time), overall and per
    kind of frame.

    Example: OMP_NUM_THREADS=1 posedrift bench track --frames 300 --repeats 3 --json track.json

    Example: posedrift bench track --room --camera d435 --distance 2.0

    Example: posedrift bench track --net none   # the forest labels the pixels
    """
    import json

    from rich.console import Console
    from rich.markdown import Markdown

    from posedrift.benchmarks._track import bench_track, render_sequences

    if stage_clock not in ("cpu", "wall"):
        raise fail(f"--stage-clock must be 'cpu' or 'wall'. Got {stage_clock!r}.")
    placement = {"distance": distance, "room": room}
    if camera is not None:
        from posedrift.camera import CAMERA_PRESETS

        if camera not in CAMERA_PRESETS:
            raise fail(f"--camera must be one of {', '.join(CAMERA_PRESETS)}. Got {camera!r}.")
        placement["intrinsics"] = CAMERA_PRESETS[camera]
    part_net = load_part_net(net, turned_net)
    try:
        if progress_enabled():
            from rich.progress import Progress

            with Progress(transient=True) as progress:
                task = progress.add_task("rendering", total=None)

                def on_frame(done: int, total: int) -> None:
                    progress.update(task, completed=done, total=total)

                sequences = render_sequences(
                    bvh or (), frames=frames, on_frame=on_frame, **placement
                )
        else:
            sequences = render_sequences(bvh or (), frames=frames, **placement)
        result = bench_track(
            sequences,
            n_points=points,
            repeats=repeats,
            stage_clock=stage_clock,
            scene="room (floor, wall, depth noise)" if room else "",
            tracker_options=None if part_net is None else {"part_net": part_net},
        )
    except ValueError as exc:
        raise fail(str(exc)) from exc
    text = result.markdown()
    if progress_enabled():
        Console().print(Markdown(text))
    else:
        typer.echo(text)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(result.to_dict(), indent=2) + "\n")
        typer.echo(f"-> {json_out}")
