"""Write docs/cli.md, the reference of every ``posedrift`` command and option.

The page is generated from the command-line app itself (the same text as ``--help``),
so it cannot drift from the code; ``tests/test_cli_reference.py`` fails when the
committed page differs from what this script writes.

Usage::

    python scripts/cli_reference.py            # rewrites docs/cli.md
    python scripts/cli_reference.py --check    # exit 1 if docs/cli.md is out of date
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import typer

from posedrift.cli import app

PAGE = Path(__file__).resolve().parents[1] / "docs" / "cli.md"


def _is_argument(param) -> bool:
    return param.param_type_name == "argument"


def _default(param) -> str:
    """The default as the reference shows it (typer's click is vendored: duck-typed)."""
    if param.required:
        return "required"
    default = param.default
    if default is None or callable(default):
        return ""
    if getattr(param, "is_flag", False) and param.secondary_opts:
        names = param.opts if default else param.secondary_opts
        return f"`{names[0]}`"
    if isinstance(default, bool):
        return ""
    return f"`{default}`"


def _options(command) -> list[str]:
    rows = []
    for param in command.params:
        if _is_argument(param):
            name = f"`{param.name.upper()}`" + (" ..." if param.nargs == -1 else "")
            text = (getattr(param, "help", None) or "").replace("|", "\\|").replace("\n", " ")
        else:
            if param.hidden or param.name == "help":
                continue
            name = " / ".join(f"`{o}`" for o in [*param.opts, *param.secondary_opts])
            text = (param.help or "").replace("|", "\\|").replace("\n", " ")
        rows.append(f"| {name} | {_default(param)} | {text} |")
    return rows


def _describe(command, path: str, out: list[str]) -> None:
    if hasattr(command, "commands"):  # a group
        for name in sorted(command.commands):
            _describe(command.commands[name], f"{path} {name}", out)
        return
    out.append(f"## `{path}`")
    out.append("")
    for paragraph in (command.help or "").split("\n\n"):
        out.append(" ".join(line.strip() for line in paragraph.splitlines()).strip())
        out.append("")
    rows = _options(command)
    if rows:
        out += ["| Argument or option | Default | Meaning |", "|---|---|---|", *rows]
        out.append("")


def render() -> str:
    """The text of docs/cli.md."""
    root = typer.main.get_command(app)
    out = [
        "# Command reference",
        "",
        "Generated from the command-line app by `python scripts/cli_reference.py`; the same",
        "text as each command's `--help`. Global options, before the command: `-q` / `--quiet`",
        "(no progress bars or informational messages) and `-v` / `--verbose` (debug logging).",
        "Exit status: 0 success, 1 some input skipped or unreadable (the rest processed and",
        "written), 2 unusable input or options, 130 interrupted.",
        "",
    ]
    _describe(root, "posedrift", out)
    return "\n".join(out).rstrip() + "\n"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--check", action="store_true", help="only compare, write nothing")
    args = parser.parse_args()
    text = render()
    if args.check:
        current = PAGE.read_text() if PAGE.exists() else ""
        if current != text:
            print(f"{PAGE} is out of date: run python scripts/cli_reference.py", file=sys.stderr)
            return 1
        return 0
    PAGE.write_text(text)
    print(f"wrote {PAGE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
