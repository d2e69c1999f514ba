"""Mean-shift part modes (paper, Section 3.4): ground truth, identity, and the fast kernel."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.skeleton import part_modes
from posedrift.skeleton._meanshift import _shift_modes


def _assert_same(got, ref, kernel):
    """Bit for bit in NumPy; the compiled kernel's exp may differ in the last bit."""
    if kernel == "numpy":
        np.testing.assert_array_equal(got, ref)
    else:
        np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)  # a picometre


def _reference_modes(points, labels, *, bandwidth, weights=None, n_parts=15, max_iter=20, tol=1e-4):
    """The per-coordinate version ``part_modes`` replaced; it must agree bit for bit."""
    w = np.ones(len(points)) if weights is None else np.asarray(weights, dtype=float)
    ok = (labels >= 0) & (labels < n_parts)
    p, lab, w = points[ok], labels[ok], w[ok]
    counts = np.bincount(lab, weights=w, minlength=n_parts)
    modes = np.full((n_parts, 3), np.nan)
    have = counts > 0
    if not have.any():
        return modes, counts
    for d in range(3):
        modes[have, d] = np.bincount(lab, weights=w * p[:, d], minlength=n_parts)[have]
        modes[have, d] /= counts[have]
    inv2h2 = 0.5 / bandwidth**2
    for _ in range(max_iter):
        k = w * np.exp(-((p - modes[lab]) ** 2).sum(axis=1) * inv2h2)
        den = np.bincount(lab, weights=k, minlength=n_parts)
        new = modes.copy()
        move = have & (den > 1e-12)
        for d in range(3):
            new[move, d] = np.bincount(lab, weights=k * p[:, d], minlength=n_parts)[move]
            new[move, d] /= den[move]
        shift = np.nanmax(np.abs(new - modes)) if move.any() else 0.0
        modes = new
        if shift < tol:
            break
    return modes, counts


def test_mode_of_a_skewed_blob_is_its_peak():
    rng = np.random.default_rng(0)
    peak = np.array([0.1, -0.3, 2.5])
    core = rng.normal(peak, 0.01, size=(300, 3))
    tail = rng.normal(peak + [0.15, 0, 0], 0.03, size=(100, 3))  # drags the mean 4 cm away
    points = np.vstack([core, tail])
    modes = part_modes(points, np.zeros(400, int), bandwidth=0.03, max_iter=100, tol=1e-7)
    assert np.linalg.norm(modes[0] - peak) < 0.003  # within 3 mm of the peak
    assert np.linalg.norm(points.mean(axis=0) - peak) > 0.03
    assert np.isnan(modes[1:]).all()


def test_single_point_parts_are_their_own_modes():
    points = np.arange(45, dtype=float).reshape(15, 3)
    np.testing.assert_array_equal(part_modes(points, np.arange(15)), points)


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_part_modes_equal_the_reference(seed, meanshift_kernel):
    rng = np.random.default_rng(seed)
    centres = rng.uniform(-0.8, 0.8, size=(15, 3))
    labels = rng.integers(-2, 17, size=400)  # some unknown and out-of-range labels
    labels[labels == 6] = 5  # a part without points
    points = centres[np.clip(labels, 0, 14)] + rng.normal(scale=0.07, size=(400, 3))
    weights = rng.random(400)
    weights[labels == 9] = 0.0  # a part with zero total weight
    cases = [
        {"bandwidth": 0.06},
        {"bandwidth": 0.08, "weights": weights},
        {"bandwidth": 0.02, "max_iter": 60, "tol": 1e-8},
        {"bandwidth": 0.5, "max_iter": 3},
    ]
    for case in cases:
        got = part_modes(points, labels, return_counts=True, **case)
        ref = _reference_modes(points, labels, **case)
        _assert_same(got[0], ref[0], meanshift_kernel)
        np.testing.assert_array_equal(got[1], ref[1])
    far = np.where(labels == 3, labels, 0)  # a part whose points are all far from its mean
    far_points = points.copy()
    far_points[labels == 3] += rng.choice([-5.0, 5.0], size=(np.sum(labels == 3), 1))
    _assert_same(
        part_modes(far_points, far, bandwidth=0.01),
        _reference_modes(far_points, far, bandwidth=0.01)[0],
        meanshift_kernel,
    )


def test_shift_modes_stops_drops_and_keeps(meanshift_kernel):
    # Two groups around known centres, one group far from all its points, one not live.
    rng = np.random.default_rng(4)
    truth = np.array([[0.0, 0.0, 2.0], [0.3, 0.1, 2.5]])
    coords = np.vstack([rng.normal(truth[0], 0.005, (50, 3)), rng.normal(truth[1], 0.005, (50, 3))])
    coords = np.vstack([coords, [[9.0, 9.0, 9.0]], [[1.0, 1.0, 1.0]]])
    group = np.r_[np.zeros(50, int), np.ones(50, int), 2, 3]
    start = np.array([[0.01, 0.0, 2.0], [0.3, 0.11, 2.5], [0.0, 0.0, 0.0], [np.nan] * 3])
    for drop_lost in (False, True):
        centre, live = start.copy(), np.array([True, True, True, False])
        steps = _shift_modes(
            coords, group, np.ones(len(group)), centre, live, scale=-0.5 / 0.02**2,
            max_iter=50, tol=1e-9, min_mass=1e-9, drop_lost=drop_lost,
        )  # fmt: skip
        assert 1 < steps < 50  # converged before the limit
        assert np.abs(centre[:2] - truth).max() < 0.003  # within 3 mm of the blobs' centres
        np.testing.assert_array_equal(centre[2], start[2])  # its point is 15 m away: stays
        assert np.isnan(centre[3]).all()  # not live: untouched
        assert live.tolist() == [True, True, not drop_lost, False]
    # Identity: a single point per group is its own mode after one step.
    centre, live = coords[:2].copy(), np.ones(2, bool)
    _shift_modes(
        coords[:2], np.arange(2), np.ones(2), centre, live, scale=-100.0, max_iter=5, tol=0.0,
        min_mass=0.0, drop_lost=True,
    )  # fmt: skip
    np.testing.assert_array_equal(centre, coords[:2])


def test_part_modes_errors_and_empty_input():
    assert np.isnan(part_modes(np.zeros((0, 3)), np.zeros(0, int))).all()
    with pytest.raises(ValueError, match="'labels' argument of part_modes"):
        part_modes(np.zeros((4, 3)), np.zeros(3, int))
    with pytest.raises(ValueError, match="'weights' argument of part_modes"):
        part_modes(np.zeros((4, 3)), np.zeros(4, int), weights=-np.ones(4))
