"""``benchmarks/track_fingerprint.py``: the tracker's outputs saved and compared bit for bit."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
track_fingerprint = pytest.importorskip("track_fingerprint")


def test_the_same_code_gives_the_same_outputs_and_a_change_is_named(tmp_path, capsys):
    first, second = tmp_path / "first.npz", tmp_path / "second.npz"
    assert track_fingerprint.main([str(first), "--frames", "6"]) == 0
    assert track_fingerprint.main([str(second), "--frames", "6", "--compare", str(first)]) == 0
    assert "identical" in capsys.readouterr().out
    with np.load(first) as saved:
        outputs = dict(saved)
    assert outputs["builtin|0|status"] == "reinitialized"
    assert outputs["builtin|5|joints"].shape == (15, 3)
    outputs["builtin|3|joints"] = outputs["builtin|3|joints"] + 1e-12  # one bit is enough
    del outputs["builtin|5|labels"]
    with np.load(second) as saved:
        assert track_fingerprint.differences(outputs, saved) == [
            "builtin|3|joints",
            "builtin|5|labels",
        ]
    tampered = tmp_path / "tampered.npz"
    np.savez(tampered, **outputs)
    assert track_fingerprint.main([str(second), "--frames", "6", "--compare", str(tampered)]) == 1
    assert "2 arrays differ" in capsys.readouterr().out
