"""The prediction benchmark of ``benchmarks/carried_joints_figure.py`` (it reads ground truth)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from posedrift.synthetic import build_sequence, procedural_motion

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
carried = pytest.importorskip("carried_joints_figure")


def test_carried_joints_are_the_field_near_the_template_and_within_centimetres():
    sequence = build_sequence(procedural_motion(fps=30.0), n_frames=40, in_place=True, rng=0)
    m = carried.measure(sequence)
    n = len(m["gap"])
    assert n % 15 == 0 and n >= 15 * 35  # every joint of (nearly) every frame after the first
    assert all(len(v) == n for v in m.values())
    near = m["gap"] < 3.0  # centimetres: the carried joints are the field there
    assert near.any()
    np.testing.assert_allclose(m["carried"][near], m["field"][near], atol=1e-9)
    # The built-in motion moves a few centimetres a frame: the predictions are that good.
    assert np.median(m["carried"]) < 3.0 and np.median(m["true"]) < 5.0
    rows = carried.table(m)
    assert sum(r[2] for r in rows) == n
