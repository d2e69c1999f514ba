"""docs/cli.md is generated from the command-line app: it must match the code."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _script():
    path = ROOT / "scripts" / "cli_reference.py"
    spec = importlib.util.spec_from_file_location("cli_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_command_reference_is_current():
    script = _script()
    text = script.render()
    assert (ROOT / "docs/cli.md").read_text() == text, (
        "docs/cli.md is out of date: run python scripts/cli_reference.py"
    )
    # Every command and every option of `track` are there.
    for command in ("track", "demo", "view", "synth", "train", "eval synthetic", "eval utd"):
        assert f"## `posedrift {command}`" in text
    for option in ("--point-clouds", "--convention", "--no-video", "--depth-scale"):
        assert f"`{option}`" in text
