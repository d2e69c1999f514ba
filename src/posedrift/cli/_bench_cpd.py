"""``posedrift bench cpd``: posedrift's CPD against its peers, one process, same inputs."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from posedrift.cli._app import bench_app, fail, progress_enabled


@bench_app.command("cpd")
def bench_cpd_command(
    sizes: Annotated[
        str, typer.Option("--sizes", help="Comma-separated source sizes M.")
    ] = "400,2000,10000",
    threads: Annotated[
        str, typer.Option("--threads", help="Comma-separated thread limits; 'all' = no limit.")
    ] = "1,all",
    repeats: Annotated[int, typer.Option("--repeats", min=1, help="Timed repeats (median).")] = 5,
    seed: Annotated[int, typer.Option("--seed", help="Seed of the inputs.")] = 0,
    frame_points: Annotated[
        int, typer.Option("--frame-points", min=10, help="Points of the frame-to-frame pair.")
    ] = 400,
    impls: Annotated[
        str | None,
        typer.Option(
            "--impls",
            help="Comma-separated implementations to run, e.g. posedrift,pycpd (default all; "
            "an unknown name lists the known ones).",
        ),
    ] = None,
    json_out: Annotated[
        Path | None, typer.Option("--json", help="Write the full result as JSON here.")
    ] = None,
    markdown_out: Annotated[
        Path | None, typer.Option("--markdown", help="Write the Markdown table here.")
    ] = None,
) -> None:
    """Time nonrigid CPD (posedrift, pycpd, probreg, ...) on a warped humanoid with outliers.

    Per implementation and size: median wall and CPU (process) time, iterations, RMS
    error to the true correspondences and peak memory, under each thread limit; plus
    cold vs warm-started frame-to-frame registrations (defaults, float32, exact, low rank).
    Missing peers are reported as skipped.

    Example: posedrift bench cpd --sizes 400,2000,10000 --json cpd.json --markdown cpd.md
    """
    import json

    from posedrift.benchmarks._cpd import implementations, markdown_table, run_cpd_benchmark
    from posedrift.cli._outputs import check_output_file

    try:
        size_list = [int(s) for s in sizes.split(",") if s.strip()]
        thread_list = [None if t.strip() == "all" else int(t) for t in threads.split(",")]
    except ValueError as exc:
        raise fail(
            f"--sizes and --threads take comma-separated integers ('all' for threads): {exc}"
        ) from exc
    if not size_list or min(size_list) < 10:
        raise fail(f"--sizes must list sizes of at least 10 points. Got {sizes!r}.")
    if any(t is not None and t < 1 for t in thread_list):
        raise fail(f"--threads must be positive or 'all'. Got {threads!r}.")
    only = None
    if impls is not None:
        only = [name.strip() for name in impls.split(",") if name.strip()]
        # Some implementations exist only at some sizes (exact solves up to 3000 points...).
        known = list(dict.fromkeys(n for size in size_list for n in implementations(size)))
        unknown = [name for name in only if name not in known]
        if unknown or not only:
            what = (
                f"{', '.join(unknown)}: no such implementation at --sizes "
                f"{','.join(map(str, size_list))}"
                if only
                else f"{impls!r} names no implementation"
            )
            raise fail(f"--impls {what}. Known at these sizes: {', '.join(known)}.")
    if json_out is not None:
        check_output_file(json_out, "--json")
    if markdown_out is not None:
        check_output_file(markdown_out, "--markdown")
    say = (lambda msg: typer.echo(f"  {msg}", err=True)) if progress_enabled() else None
    report = run_cpd_benchmark(
        size_list,
        threads=thread_list,
        repeats=repeats,
        rng=seed,
        progress=say,
        frame_points=frame_points,
        only=only,
    )
    table = markdown_table(report)
    typer.echo(table)
    if json_out is not None:
        json_out.parent.mkdir(parents=True, exist_ok=True)
        json_out.write_text(json.dumps(report, indent=2) + "\n")
        typer.echo(f"-> {json_out}")
    if markdown_out is not None:
        markdown_out.parent.mkdir(parents=True, exist_ok=True)
        markdown_out.write_text(table)
        typer.echo(f"-> {markdown_out}")
