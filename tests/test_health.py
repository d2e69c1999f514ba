"""The track's health checks and the initialization's label votes: the fast versions against
the originals (kept verbatim below, docstrings dropped), bit for bit."""

from __future__ import annotations

import numpy as np
import pytest

from posedrift.skeleton._definitions import JOINT_INDEX, PART_JOINTS, PART_NAMES
from posedrift.skeleton._tpose import t_pose_joints
from posedrift.tracking._health import (
    _PART_REACH,
    Health,
    _joint_gaps,
    assess,
    bone_distances,
    unexplained_share,
)
from posedrift.tracking._init import label_template_points, smooth_labels

_J = JOINT_INDEX


def _ref_segments(joints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    j = joints
    pelvis = 0.5 * (j[_J["right_hip"]] + j[_J["left_hip"]])
    named = {name: j[i] for name, i in _J.items()}
    named["pelvis"] = pelvis
    for side in ("right", "left"):
        fore = j[_J[f"{side}_hand"]] - j[_J[f"{side}_elbow"]]
        named[f"{side}_hand_tip"] = j[_J[f"{side}_hand"]] + 0.6 * fore
        shank = j[_J[f"{side}_foot"]] - j[_J[f"{side}_knee"]]
        named[f"{side}_toe"] = j[_J[f"{side}_foot"]] + 0.15 * shank
    starts = np.array([named[a] for a, _ in PART_JOINTS])
    ends = np.array([named[b] for _, b in PART_JOINTS])
    # The torso parts are wide: widen their "bones" to the shoulders and hips.
    return starts, ends


def _ref_bone_distances(points: np.ndarray, labels: np.ndarray, joints: np.ndarray) -> np.ndarray:
    starts, ends = _ref_segments(np.asarray(joints, dtype=float))
    lab = np.asarray(labels).astype(np.int64)
    ok = (lab >= 0) & (lab < len(PART_NAMES))
    out = np.full(len(points), np.nan)
    if not ok.any():
        return out
    a, b = starts[lab[ok]], ends[lab[ok]]
    ab = b - a
    denom = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", points[ok] - a, ab) / np.where(denom > 0, denom, 1.0), 0, 1)
    out[ok] = np.linalg.norm(points[ok] - (a + t[:, None] * ab), axis=1)
    return out


def _ref_assess(
    points: np.ndarray,
    labels: np.ndarray,
    joints: np.ndarray,
    measured: np.ndarray,
    *,
    height: float,
    sigma: float | None = None,
    max_unexplained: float = 0.2,
    max_sigma: float = 0.08,
    min_measured: float = 0.5,
    slack: float = 0.06,
    max_joint_gap: float = 0.15,
) -> Health:
    joints = np.asarray(joints, dtype=float)
    meas = float(np.mean(measured))
    if not np.isfinite(joints).all():
        return Health(False, "the skeleton has unknown joints", np.inf, 1.0, meas)
    dist = _ref_bone_distances(points, labels, joints)
    lab = np.asarray(labels).astype(np.int64)
    reach = _PART_REACH * (height / 1.75)
    limit = np.where((lab >= 0) & (lab < len(reach)), reach[np.clip(lab, 0, 14)] + slack, 0.0)
    bad = ~np.isfinite(dist) | (dist > limit)
    unexplained = float(np.mean(bad)) if len(bad) else 1.0
    score = unexplained + 0.5 * (1.0 - meas)
    if sigma is not None and np.isfinite(sigma):
        score += max(0.0, sigma - 0.02)
    if unexplained > max_unexplained:
        return Health(
            False,
            f"{100 * unexplained:.0f}% of the points are far from their part's bone",
            score,
            unexplained,
            meas,
        )
    if meas < min_measured:
        return Health(
            False,
            f"only {100 * meas:.0f}% of the joints are supported by the labels",
            score,
            unexplained,
            meas,
        )
    limbs = [_J[n] for n in _J if n.endswith(("elbow", "hand", "knee", "foot"))]
    gaps = np.sqrt(((joints[limbs, None, :] - points[None, :, :]) ** 2).sum(-1).min(axis=1))
    if gaps.max() > max_joint_gap * (height / 1.75):
        worst = list(_J)[limbs[int(np.argmax(gaps))]]
        return Health(
            False,
            f"the {worst} is {100 * gaps.max():.0f} cm from the body",
            score + 0.5,
            unexplained,
            meas,
        )
    if sigma is not None and np.isfinite(sigma) and sigma > max_sigma:
        return Health(
            False, f"the registration residual is {100 * sigma:.1f} cm", score, unexplained, meas
        )
    return Health(True, "", score, unexplained, meas)


def _ref_label_template_points(
    points: np.ndarray, pixel_points: np.ndarray, pixel_labels: np.ndarray, *, k: int = 5
) -> np.ndarray:
    from scipy.spatial import cKDTree

    known = pixel_labels >= 0
    if not known.any():
        return np.full(len(points), -1, dtype=np.int64)
    kk = min(k, int(known.sum()))
    _, idx = cKDTree(pixel_points[known]).query(points, k=kk)
    idx = np.asarray(idx).reshape(len(points), kk)
    votes = pixel_labels[known][idx]
    counts = np.zeros((len(points), 15))
    np.add.at(counts, (np.repeat(np.arange(len(points)), kk), votes.ravel()), 1.0)
    return np.argmax(counts, axis=1).astype(np.int64)


def _ref_smooth_labels(labels: np.ndarray, rows: np.ndarray, cols: np.ndarray, n_iter: int = 2):
    labels = np.asarray(labels).astype(np.int64).copy()
    n = len(labels)
    for _ in range(n_iter):
        counts = np.zeros((n, 15))
        ok = labels >= 0
        counts[np.nonzero(ok)[0], labels[ok]] += 1.5
        for a, b in ((rows, cols), (cols, rows)):
            good = labels[b] >= 0
            np.add.at(counts, (a[good], labels[b][good]), 1.0)
        has = counts.sum(axis=1) > 0
        labels[has] = np.argmax(counts[has], axis=1)
    return labels


def _assert_same(new, ref):
    if isinstance(ref, Health):
        assert (new.ok, new.reason) == (ref.ok, ref.reason)
        for field in ("score", "unexplained", "measured"):
            a, b = getattr(new, field), getattr(ref, field)
            assert type(a) is type(b) and (a == b or (a != a and b != b)), field
    else:
        new, ref = np.asarray(new), np.asarray(ref)
        assert new.dtype == ref.dtype
        np.testing.assert_array_equal(new, ref, strict=True)


def _body(rng, n=400):
    """Points scattered about a T-pose's bones, labelled by part, and the skeleton."""
    joints = t_pose_joints(1.75) + [0.0, 0.0, 2.5]
    ext = {name: joints[i] for name, i in _J.items()}
    ext["pelvis"] = 0.5 * (ext["right_hip"] + ext["left_hip"])
    for side in ("right", "left"):
        ext[f"{side}_hand_tip"] = ext[f"{side}_hand"] + [0.0, 0.08, 0.0]
        ext[f"{side}_toe"] = ext[f"{side}_foot"] + [0.0, 0.0, -0.1]
    labels = rng.integers(0, len(PART_NAMES), size=n)
    t = rng.random((n, 1))
    starts = np.array([ext[a] for a, _ in PART_JOINTS])[labels]
    ends = np.array([ext[b] for _, b in PART_JOINTS])[labels]
    points = starts + t * (ends - starts) + rng.normal(scale=0.05, size=(n, 3))
    return points, labels, joints


@pytest.mark.parametrize("seed", range(40))
def test_fast_health_matches_the_original_bit_for_bit(seed):
    rng = np.random.default_rng(seed)
    points, labels, joints = _body(rng, int(rng.integers(30, 600)))
    joints = joints + rng.normal(scale=rng.choice([0.01, 0.05, 0.2]), size=joints.shape)
    if rng.random() < 0.3:
        labels[rng.random(len(labels)) < 0.1] = -1
    if rng.random() < 0.2:
        joints[rng.integers(0, 15)] = np.nan
    if rng.random() < 0.3:  # a hand floating beside the body
        joints[_J["left_hand"]] += [0.5, 0.0, 0.0]
    measured = rng.random(15) < rng.choice([0.3, 0.9, 1.0])
    kwargs = {"height": rng.uniform(1.4, 1.95), "sigma": rng.choice([None, np.nan, 0.01, 0.1])}
    kwargs["max_unexplained"] = rng.choice([0.2, 0.9])
    _assert_same(
        bone_distances(points, labels, joints), _ref_bone_distances(points, labels, joints)
    )
    _assert_same(
        assess(points, labels, joints, measured, **kwargs),
        _ref_assess(points, labels, joints, measured, **kwargs),
    )


def test_health_reports_a_floating_joint_and_all_unknown_labels():
    rng = np.random.default_rng(0)
    points, labels, joints = _body(rng)
    joints[_J["right_foot"]] += [0.0, 0.0, -0.6]
    health = assess(points, labels, joints, np.ones(15, bool), height=1.75, max_unexplained=1.0)
    assert not health.ok and health.reason.startswith("the right_foot is")
    assert np.isnan(bone_distances(points, np.full(len(points), -1), joints)).all()
    assert _PART_REACH.shape == (15,)
    # A foot outside the camera's view (below the image) is not judged by its gap.
    in_view = np.ones(15, bool)
    in_view[_J["right_foot"]] = False
    kw = {"height": 1.75, "max_unexplained": 1.0}
    assert assess(points, labels, joints, np.ones(15, bool), in_view=in_view, **kw).ok
    in_view[_J["right_foot"]], in_view[_J["left_hand"]] = True, False
    assert not assess(points, labels, joints, np.ones(15, bool), in_view=in_view, **kw).ok


@pytest.mark.parametrize("seed", range(12))
def test_fast_label_votes_match_the_original(seed):
    rng = np.random.default_rng(seed)
    points, labels, _ = _body(rng, 300)
    pixels, pixel_labels, _ = _body(rng, 2000)
    pixels = np.round(pixels, 2)  # on a grid: equidistant pixels, as in a depth image
    pixel_labels[rng.random(len(pixel_labels)) < 0.2] = -1
    for k in (1, 5):
        _assert_same(
            label_template_points(points, pixels, pixel_labels, k=k),
            _ref_label_template_points(points, pixels, pixel_labels, k=k),
        )
    rows, cols = rng.integers(0, len(points), size=(2, 5 * len(points)))
    noisy = np.where(rng.random(len(labels)) < 0.2, -1, labels)
    for n_iter in (1, 2, 3):
        _assert_same(
            smooth_labels(noisy, rows, cols, n_iter=n_iter),
            _ref_smooth_labels(noisy, rows, cols, n_iter=n_iter),
        )
    none = np.full(len(points), -1)
    _assert_same(label_template_points(points, pixels, none), np.full(len(points), -1))
    _assert_same(smooth_labels(none, rows, cols), _ref_smooth_labels(none, rows, cols))


def test_joint_gaps_match_the_original_expression():
    rng = np.random.default_rng(3)
    for _ in range(20):
        points = rng.normal(size=(int(rng.integers(1, 500)), 3)) * rng.uniform(0.01, 3.0)
        joints = rng.normal(size=(8, 3))
        ref = np.sqrt(((joints[:, None, :] - points[None, :, :]) ** 2).sum(-1).min(axis=1))
        _assert_same(_joint_gaps(points, joints), ref)


def test_unexplained_share_counts_points_far_from_their_bone():
    rng = np.random.default_rng(5)
    points, labels, joints = _body(rng)
    # Identity: points on their own part's bone are all explained, even with no slack.
    starts, ends = _ref_segments(joints)
    on_bones = starts[labels] + rng.random((len(labels), 1)) * (ends - starts)[labels]
    assert unexplained_share(on_bones, labels, joints, height=1.75, slack=0.0) == 0.0
    # A metre away from the body every point is unexplained; with no points, all are.
    assert unexplained_share(on_bones + [1.0, 0.0, 0.0], labels, joints, height=1.75) == 1.0
    assert unexplained_share(points[:0], labels[:0], joints, height=1.75) == 1.0
    # Unknown labels count as far; the health check reports the same share.
    labels[:40] = -1
    share = unexplained_share(points, labels, joints, height=1.8)
    health = assess(points, labels, joints, np.ones(15, bool), height=1.8, max_unexplained=1.0)
    assert share == health.unexplained and share >= 40 / len(points)
