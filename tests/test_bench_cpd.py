"""The CPD benchmark: inputs with known truth, the runner, and ``posedrift bench cpd``."""

from __future__ import annotations

import json

import numpy as np
from typer.testing import CliRunner

from posedrift.benchmarks import _cpd
from posedrift.cli import app


def test_problem_has_known_truth_and_outliers():
    prob = _cpd.make_problem(200, rng=0)
    assert prob["source"].shape == (200, 3) and prob["truth"].shape == (200, 3)
    assert prob["target"].shape == (220, 3)  # 10% outliers
    motion = _cpd.rms(prob["source"], prob["truth"])
    assert 0.02 < motion < 0.2  # centimetres of smooth motion, in metres
    # every true position is in the target, up to the 3 mm noise
    d = np.linalg.norm(prob["truth"][:, None] - prob["target"][None], axis=2).min(axis=1)
    assert np.percentile(d, 95) < 0.01


def test_frame_pair_is_a_small_motion():
    pair = _cpd.make_frame_pair(150, rng=1)
    f0, f1, f2 = pair["frames"]
    assert f0.shape == f1.shape == f2.shape == (150, 3)
    assert 0.003 < _cpd.rms(f1, pair["truth12"]) < 0.05


def test_cli_bench_cpd_writes_json_and_markdown(tmp_path):
    out = tmp_path / "cpd.json"
    md = tmp_path / "cpd.md"
    result = CliRunner().invoke(
        app,
        [
            "-q",
            "bench",
            "cpd",
            "--sizes",
            "60",
            "--threads",
            "1",
            "--repeats",
            "1",
            "--frame-points",
            "60",
            "--impls",
            "posedrift,posedrift-lowrank100,cpd-pytorch",
            "--json",
            str(out),
            "--markdown",
            str(md),
        ],
    )
    assert result.exit_code == 0, result.output
    report = json.loads(out.read_text())
    assert report["machine"]["logical_cores"] >= 1
    rows = {r["impl"]: r for r in report["results"]}
    assert set(rows) == {"posedrift", "posedrift-lowrank100", "cpd-pytorch"}
    # registration brings the source closer to the truth than no motion at all
    assert rows["posedrift"]["rms_m"] < 0.5 * report["truth_motion_rms_m"]["60"]
    assert rows["posedrift"]["iterations"] > 0 and rows["posedrift"]["peak_mib"] > 0
    assert "cpd-pytorch" in rows and "skipped" in rows["cpd-pytorch"]
    assert set(report["frame_to_frame"]) >= {"cold", "warm", "no_motion_rms_m"}
    assert "| 60 | 1 | posedrift |" in md.read_text()


def test_cli_bench_cpd_rejects_bad_sizes():
    result = CliRunner().invoke(app, ["bench", "cpd", "--sizes", "abc"])
    assert result.exit_code != 0
    assert "--sizes" in result.output


def test_cli_bench_cpd_rejects_unknown_impls(monkeypatch):
    def no_work(*args, **kwargs):
        raise AssertionError("unknown --impls must be rejected before any work")

    monkeypatch.setattr(_cpd, "run_cpd_benchmark", no_work)
    result = CliRunner().invoke(
        app, ["bench", "cpd", "--impls", "posedrift,foo", "--sizes", "50", "--repeats", "1"]
    )
    assert result.exit_code == 2
    assert "--impls foo: no such implementation at --sizes 50. Known at these sizes: " in (
        result.stderr
    )
    known = result.stderr.split("Known at these sizes: ")[1].rstrip(".\n").split(", ")
    assert known == list(_cpd.implementations(50))
    assert "posedrift-scaled-smoothness" not in known  # only above 400 points
    result = CliRunner().invoke(app, ["bench", "cpd", "--impls", ",", "--sizes", "50"])
    assert result.exit_code == 2 and "--impls ',' names no implementation" in result.stderr
