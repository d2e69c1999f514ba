"""The perfect-label controls of ``benchmarks/label_oracle.py`` (they read ground truth)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from posedrift.synthetic import build_sequence, procedural_motion
from posedrift.tracking import PoseTracker

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
label_oracle = pytest.importorskip("label_oracle")


@pytest.fixture(scope="module")
def sequence():
    return build_sequence(procedural_motion(fps=30.0), n_frames=40, in_place=True, rng=0)


def _error(angles: np.ndarray, sequence) -> float:
    return float(np.nanmean(np.abs(angles - sequence.reference.angles)))


def test_true_label_forest_answers_each_pixel_with_its_true_part(sequence):
    forest = label_oracle.TrueLabelForest()
    frame = sequence.frames[5]
    forest.truth = sequence.reference.labels[5]
    mask = forest.truth > 0
    pred = forest.predict(frame.depth, mask, frame.intrinsics)
    np.testing.assert_array_equal(pred.labels[mask], forest.truth[mask].astype(int) - 1)
    assert np.all(pred.labels[~mask] == -1)
    probs = forest.predict_pixels(frame.depth, pred.pixels[:50], frame.intrinsics, mask=mask)
    np.testing.assert_allclose(probs.sum(axis=1), 1.0, rtol=1e-6)
    assert np.all(probs.argmax(axis=1) == pred.labels[pred.pixels[:50, 0], pred.pixels[:50, 1]])


def test_both_controls_recover_the_angles_within_a_few_degrees(sequence):
    forest = label_oracle.TrueLabelForest()
    tracker = PoseTracker(sequence.frames[0].intrinsics, forest=forest, decimation=1)
    tracked = label_oracle.tracked_angles(sequence, tracker, forest)
    assert np.isfinite(tracked).all()
    assert _error(tracked, sequence) < 4.0  # degrees
    true = label_oracle.true_label_angles(sequence, tracker.calibration)
    assert np.mean(np.isfinite(true)) > 0.95
    assert _error(true, sequence) < 4.0
