"""The perfect-label controls of ``benchmarks/label_oracle.py`` (they read ground truth)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from posedrift.skeleton import facing_yaw, joint_angles, t_pose_joints
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
    tracked = joint_angles(label_oracle.tracked_joints(sequence, tracker, forest))
    assert np.isfinite(tracked).all()
    assert _error(tracked, sequence) < 4.0  # degrees
    true = joint_angles(label_oracle.true_label_joints(sequence, tracker.calibration))
    assert np.mean(np.isfinite(true)) > 0.95
    assert _error(true, sequence) < 4.0


def _turned(degrees: float) -> np.ndarray:
    """A T-pose 3 m in front of the camera, turned ``degrees`` about the vertical."""
    a = np.radians(degrees)
    turn = np.array([[np.cos(a), 0.0, np.sin(a)], [0.0, 1.0, 0.0], [-np.sin(a), 0.0, np.cos(a)]])
    world = t_pose_joints(1.75) @ turn.T  # +Y up, facing +Z before the turn
    return world * [1.0, -1.0, -1.0] + [0.0, 0.0, 3.0]


def test_facing_cells_give_the_median_yaw_of_each_view_beside_the_truth():
    truth = np.stack([_turned(d) for d in (10, 20, 30, 100, 170)])
    np.testing.assert_allclose(facing_yaw(truth), [10, 20, 30, 100, 170], atol=1e-6)
    assert label_oracle.facing_cells(truth, truth) == "20 (20) / 100 (100) / 170 (170)"
    # A track that lags the turn: the same frames, each turned half as far.
    lagging = np.stack([_turned(d / 2) for d in (10, 20, 30, 100, 170)])
    assert label_oracle.facing_cells(lagging, truth) == "10 (20) / 50 (100) / 85 (170)"
    # Views with no frame, or joints that could not be placed, leave a dash.
    assert label_oracle.facing_cells(truth[:3], truth[:3]) == "20 (20) / - / -"
    unplaced = truth.copy()
    unplaced[3:] = np.nan
    assert label_oracle.facing_cells(unplaced, truth) == "20 (20) / - / -"
