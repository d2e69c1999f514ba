"""The Typer application and its command groups.

Each command lives in its own ``cli/_<name>.py`` module, is a thin wrapper over a
public function, and imports heavy modules inside its body so that
``posedrift --help`` stays fast.
"""

from __future__ import annotations

import logging
from typing import Annotated

import typer

app = typer.Typer(
    name="posedrift",
    help="3-D human pose from depth frames: nonrigid CPD body-part tracking on a CPU.\n\n"
    "Example: posedrift demo, then posedrift track recording/ --out poses/",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)
eval_app = typer.Typer(
    help="Evaluate methods against ground truth or a reference skeleton.\n\n"
    "Example: posedrift eval synthetic builtin --frames 300 --json table1.json",
    no_args_is_help=True,
)
bench_app = typer.Typer(
    help="Speed and accuracy benchmarks, peers side by side.\n\n"
    "Example: posedrift bench track --frames 300",
    no_args_is_help=True,
)
app.add_typer(eval_app, name="eval")
app.add_typer(bench_app, name="bench")


class Verbosity:
    """Process-wide verbosity chosen by ``--quiet`` / ``--verbose``."""

    quiet: bool = False


def progress_enabled() -> bool:
    """Whether long commands should draw progress bars."""
    return not Verbosity.quiet


@app.callback()
def _configure(
    quiet: Annotated[bool, typer.Option("--quiet", "-q", help="Only errors and results.")] = False,
    verbose: Annotated[bool, typer.Option("--verbose", "-v", help="Debug messages.")] = False,
) -> None:
    """posedrift: 3-D human pose from depth frames.

    Example: posedrift demo
    """
    Verbosity.quiet = quiet
    level = logging.ERROR if quiet else logging.DEBUG if verbose else logging.INFO
    logging.basicConfig(level=level, format="%(levelname)s %(name)s: %(message)s", force=True)


def fail(message: str, code: int = 2) -> typer.Exit:
    """Print ``message`` to standard error and return an Exit to raise."""
    typer.echo(f"error: {message}", err=True)
    return typer.Exit(code)
