"""``posedrift bench render``: frames per second of the depth renderer, one thread."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import bench_app, fail


@bench_app.command("render")
def bench_render_command(
    repeats: Annotated[int, typer.Option("--repeats", min=1, help="Repeats (median).")] = 7,
    frames: Annotated[int, typer.Option("--frames", min=1, help="Poses per repeat.")] = 30,
    background: Annotated[
        bool, typer.Option("--background/--no-background", help="Render floor and wall too.")
    ] = False,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write the result as JSON here.")
    ] = None,
) -> None:
    """Time the renderer at 320 x 240 on the default body, body posing excluded and included.

    One thread (BLAS pools limited with threadpoolctl; run with OMP_NUM_THREADS=1 too).
    Prints the median milliseconds and frames per second over the repeats.

    Example: OMP_NUM_THREADS=1 posedrift bench render --repeats 9 --json render.json
    """
    import json

    from posedrift.benchmarks._render import bench_render

    try:
        result = bench_render(repeats=repeats, frames=frames, background=background)
    except ValueError as exc:
        raise fail(str(exc)) from exc
    typer.echo(
        f"render {result.width}x{result.height}, {result.n_faces} faces, "
        f"{result.mean_person_pixels:.0f} person pixels, {result.threads}"
    )
    typer.echo(
        f"  rendering only:        {result.render_ms:6.2f} ms  {result.render_fps:7.1f} fps "
        f"(CPU {result.render_cpu_ms:.2f} ms; median of {repeats} x {result.frames} frames)"
    )
    typer.echo(
        f"  posing + rendering:    {result.pose_and_render_ms:6.2f} ms  "
        f"{result.pose_and_render_fps:7.1f} fps (CPU {result.pose_and_render_cpu_ms:.2f} ms)"
    )
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(result.to_dict(), indent=2) + "\n")
        typer.echo(f"  -> {json_out}")
