"""The ``posedrift`` command line: one command per user task."""

from __future__ import annotations

import importlib

from posedrift.cli._app import app

# Each module registers its commands on ``app`` (or its groups) when imported.
_COMMAND_MODULES: tuple[str, ...] = (
    "_train",
    "_eval_labels",
    "_synth",
    "_bench_render",
    "_bench_cpd",
    "_bench_track",
    "_view",
    "_eval",
    "_track",
    "_demo",
)

for _name in _COMMAND_MODULES:
    importlib.import_module(f"posedrift.cli.{_name}")


def main() -> None:
    """Entry point of the ``posedrift`` script."""
    app()


__all__ = ["app", "main"]
