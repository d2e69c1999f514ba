"""``posedrift bench track``: the tracker's per-stage timings, as a table and JSON."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from posedrift.benchmarks import bench_track, render_sequences
from posedrift.cli import app


def test_cli_bench_track_writes_table_and_json(tmp_path):
    out = tmp_path / "track.json"
    result = CliRunner().invoke(
        app, ["-q", "bench", "track", "--frames", "4", "--repeats", "2", "--json", str(out)]
    )
    assert result.exit_code == 0, result.output
    assert "| stage | tracked median ms |" in result.output
    assert "| register |" in result.output and "fps (CPU)" in result.output
    data = json.loads(out.read_text())
    assert data["frames"] == 4 and len(data["repeats_cpu_ms"]) == 2
    assert data["n_points"] == 400 and data["sequences"] == ["builtin"]
    assert data["stage_clock"] == "cpu"  # the stage timings were taken in CPU time
    assert "compiled kernels:" in data["machine"] and "machine:" in result.output
    assert any(level in data["machine"] for level in ("AVX-512", "AVX2", "NEON", "SIMD"))
    import time

    from posedrift.tracking import _tracker

    assert _tracker.time is time  # and the tracker's clock is given back
    assert sum(data["status_counts"].values()) == 4
    assert data["status_counts"]["reinitialized"] >= 1  # the first frame initializes
    stages = {s["stage"]: s for s in data["stages"]}
    assert {"segment", "points", "graph", "initialize", "total"} <= set(stages)
    assert stages["total"]["frames"] == 8  # every frame of both repeats
    # The stages add up to (about) the whole frame, and the frame rate is its inverse.
    parts = sum(s["mean_ms"] for name, s in stages.items() if name != "total")
    assert 0.8 * stages["total"]["mean_ms"] <= parts <= stages["total"]["mean_ms"] * 1.001
    assert data["fps"] == pytest.approx(1000.0 / data["cpu_ms"])
    assert 0.5 * data["cpu_ms"] < stages["total"]["mean_ms"] < 1.5 * data["cpu_ms"]


def test_bench_track_on_given_sequences_and_points():
    seqs = render_sequences(frames=3)
    assert len(seqs) == 1 and len(seqs[0].frames) == 3
    result = bench_track(seqs, n_points=150, repeats=1, stage_clock="wall")
    assert result.n_points == 150 and result.stage_clock == "wall"
    assert np.isfinite(result.reinitialized_cpu_ms) and result.reinitialized_fps > 0
    assert "| graph |" in result.markdown()


def test_bench_track_errors(tmp_path):
    runner = CliRunner()
    missing = runner.invoke(app, ["-q", "bench", "track", str(tmp_path / "nope.bvh")])
    assert missing.exit_code != 0 and "does not exist" in missing.output
    clock = runner.invoke(app, ["-q", "bench", "track", "--stage-clock", "sundial"])
    assert clock.exit_code != 0 and "--stage-clock" in clock.output
    with pytest.raises(ValueError, match="stage_clock"):
        bench_track([], stage_clock="sundial")
    with pytest.raises(ValueError, match="at least one sequence"):
        bench_track([])


def test_cli_bench_track_in_a_room_with_another_camera(tmp_path):
    out = tmp_path / "room.json"
    result = CliRunner().invoke(
        app,
        ["-q", "bench", "track", "--frames", "3", "--repeats", "1", "--room", "--camera",
         "d435", "--distance", "2.0", "--json", str(out)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    camera = json.loads(out.read_text())["camera"]
    assert camera.startswith("640x480 px, fx 385.0, person 2.0 m away") and "room" in camera
    seq = render_sequences(frames=1, room=True)[0]
    depth = seq.frames[0].depth
    assert (depth > 0).mean() > 0.5  # the floor and the wall fill the frame


def test_bench_track_rejects_an_unknown_camera():
    bad = CliRunner().invoke(app, ["-q", "bench", "track", "--camera", "pinhole9"])
    assert bad.exit_code == 2 and "--camera must be one of" in bad.output


def test_compiled_kernels_are_reported(monkeypatch):
    import importlib

    from posedrift import _build, compiled_kernels

    have = compiled_kernels()
    assert sorted(have) == sorted(_build.KERNELS)
    assert all(isinstance(v, bool) for v in have.values())
    real = importlib.import_module

    def without_mean_shift(name, *args):
        if name == "posedrift.skeleton._cmeanshift":
            raise ImportError(name)
        return real(name, *args)

    monkeypatch.setattr(importlib, "import_module", without_mean_shift)
    assert compiled_kernels()["posedrift.skeleton._cmeanshift"] is False
    assert "NumPy for skeleton._cmeanshift" in _build.compiled_summary()
