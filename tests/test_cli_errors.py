"""Unusable output paths fail up front: exit 2, the option and the path named, no work done."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from posedrift.cli import app

runner = CliRunner()


@pytest.mark.parametrize(
    ("command", "option"),
    [
        ("eval labels {missing} --json {bad}/x.json", "--json"),
        ("eval labels {missing} --json {tmp}/ok.json --png {bad}/x.png", "--png"),
        ("eval synthetic builtin --frames 5 --methods cpd --json {bad}/x.json", "--json"),
        ("eval synthetic builtin --frames 5 --figures {bad}/figs", "--figures"),
        ("eval utd {missing} --json {bad}/x.json", "--json"),
        ("train --frames 1 --out {bad}/x.npz", "--out"),
        ("train --frames 1 --out {tmp}", "--out"),
        ("synth builtin --frames 1 --out {bad}/walk", "--out"),
        ("synth builtin --frames 1 --out {tmp}/w --sheet {bad}/s.png", "--sheet"),
        ("bench cpd --sizes 50 --impls posedrift --json {bad}/x.json", "--json"),
        ("bench cpd --sizes 50 --impls posedrift --markdown {bad}/x.md", "--markdown"),
    ],
)
def test_unusable_output_path_fails_before_any_work(tmp_path, monkeypatch, command, option):
    import posedrift.labelling._train as training
    import posedrift.synthetic as synthetic

    def no_work(*args, **kwargs):
        raise AssertionError("the output path must be checked before any work")

    monkeypatch.setattr(synthetic, "build_sequence", no_work)
    monkeypatch.setattr(synthetic, "procedural_motion", no_work)
    monkeypatch.setattr(training, "training_clips", no_work)
    bad = tmp_path / "afile"
    bad.write_text("a file, not a folder")
    names = {"bad": str(bad), "tmp": str(tmp_path), "missing": str(tmp_path / "nothere")}
    args = command.format(**names).split()
    path = next(a for a in args if a.startswith(str(bad)) or a == str(tmp_path))
    result = runner.invoke(app, ["-q", *args])
    assert result.exit_code == 2, result.output
    assert f"error: {option} {path!r}" in result.stderr
    assert "Traceback" not in result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["afile"]  # nothing written
