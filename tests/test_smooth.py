"""Offline smoothing of joint paths: ``smooth_joints``, ``smooth_results`` and ``--smooth``."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
from typer.testing import CliRunner

from posedrift.camera import DepthFrame, camera_preset
from posedrift.cli import app
from posedrift.evaluation import (
    EvaluationSequence,
    Reference,
    evaluate,
    markdown_table,
    run_methods,
)
from posedrift.skeleton import joint_angles, smooth_joints, t_pose_joints
from posedrift.tracking import FrameResult, FrameStatus, LiveSmoother, smooth_results

FPS = 30.0


def _swing(n=90, noise=0.0, seed=0):
    """A hand swinging 20 cm at 1 Hz (metres, ``(n, 1, 3)``), and its frames' times."""
    t = np.arange(n) / FPS
    path = np.zeros((n, 1, 3))
    path[:, 0, 0] = 0.2 * np.sin(2 * np.pi * t)
    path[:, 0, 2] = 3.0
    noisy = path + np.random.default_rng(seed).normal(0.0, noise, path.shape)
    return path, noisy, t


def test_no_smoothing_is_the_identity():
    _, noisy, t = _swing(noise=0.01)
    out = smooth_joints(noisy, t, 0.0)
    assert out is not noisy
    np.testing.assert_array_equal(out, noisy)


def test_quadratic_and_linear_paths_are_kept_even_with_irregular_times():
    # A local quadratic fit reproduces a quadratic path: no lag, no shrinking.
    t = np.cumsum(np.r_[0.0, np.random.default_rng(1).uniform(0.02, 0.06, 79)])
    path = np.stack([0.5 * t**2, 1.0 - 0.3 * t, 3.0 + 0.1 * t], axis=1)[:, None, :]
    np.testing.assert_allclose(smooth_joints(path, t, 0.1), path, atol=1e-4)  # 0.1 mm


def test_jitter_is_removed_and_peaks_are_kept():
    path, noisy, t = _swing(noise=0.01)  # 1 cm of jitter per coordinate
    out = smooth_joints(noisy, t, 0.1)
    before = np.linalg.norm(noisy - path, axis=-1).mean()
    after = np.linalg.norm(out - path, axis=-1).mean()
    assert after < 0.6 * before
    # Without noise the swing's extremes stay within 3 mm (a Gaussian average of the
    # same width would cut them by 18%, 3.6 cm; a 7-frame moving average by 1.7 cm).
    clean = smooth_joints(path, t, 0.1)
    assert path[:, 0, 0].max() - clean[:, 0, 0].max() < 0.003
    assert np.abs(clean - path).max() < 0.004  # everywhere, the one-sided ends too


def test_unknown_frames_stay_unknown_and_split_the_path():
    n = 40
    t = np.arange(n) / FPS
    joints = np.zeros((n, 2, 3))
    joints[20:] = 1.0  # a jump, e.g. a person who left the view and came back elsewhere
    joints[19] = np.nan  # the frame between has no pose
    joints[5, 1] = np.nan  # one joint unknown in one frame
    out = smooth_joints(joints, t, 0.1)
    assert np.isnan(out[19]).all() and np.isnan(out[5, 1]).all()
    assert np.isfinite(out[5, 0]).all()
    out[5, 1] = 0.0
    np.testing.assert_allclose(out[:19], 0.0, atol=1e-12, err_msg="before")
    np.testing.assert_allclose(out[20:], 1.0, atol=1e-12, err_msg="after")


def test_single_frames_and_short_stretches_are_kept():
    t = np.arange(5) / FPS
    joints = np.array([0.0, np.nan, 0.2, 0.25, np.nan])[:, None, None] * np.ones((1, 1, 3))
    out = smooth_joints(joints, t, 0.1)
    assert out[0, 0, 0] == pytest.approx(0.0)  # alone between gaps: unchanged
    assert 0.2 <= out[2, 0, 0] <= 0.25 and 0.2 <= out[3, 0, 0] <= 0.25


@pytest.mark.parametrize(
    ("joints", "times", "sigma", "match"),
    [
        (np.zeros((4, 15)), np.arange(4.0), 0.1, r"'joints' must have shape \(T, J, 3\)"),
        (np.zeros((4, 15, 3)), np.arange(3.0), 0.1, r"'times' must have one value per frame"),
        (np.zeros((4, 15, 3)), np.array([0, 2, 1, 3.0]), 0.1, "non-decreasing"),
        (np.zeros((4, 15, 3)), np.array([0, np.nan, 1, 3.0]), 0.1, "finite"),
        (np.zeros((4, 15, 3)), np.arange(4.0), -1.0, "'sigma' must be a non-negative"),
    ],
)
def test_bad_arguments_are_named(joints, times, sigma, match):
    with pytest.raises(ValueError, match=match):
        smooth_joints(joints, times, sigma)


def _results(n=30, *, timestamps=True):
    rng = np.random.default_rng(2)
    body = t_pose_joints(1.75) * [1, -1, 1] + [0, 0.9, 3.0]
    out = []
    for i in range(n):
        stamp = i / FPS if timestamps else None
        if i == 10:
            out.append(FrameResult.empty(i, FrameStatus.LOST, "gone", timestamp=stamp))
            continue
        joints = body + rng.normal(0, 0.01, body.shape)
        status = FrameStatus.REINITIALIZED if i == 0 else FrameStatus.TRACKED
        out.append(FrameResult(i, status, joints, np.full(15, 0.9), timestamp=stamp))
    return out


def test_smooth_results_changes_the_joints_only():
    results = _results()
    out = smooth_results(results, 0.1)
    joints = np.stack([r.joints for r in results])
    expected = smooth_joints(joints, np.arange(len(results)) / FPS, 0.1)
    for before, after, want in zip(results, out, expected, strict=True):
        assert (after.index, after.status, after.timestamp) == (
            before.index,
            before.status,
            before.timestamp,
        )
        np.testing.assert_array_equal(after.confidence, before.confidence)
        np.testing.assert_array_equal(after.joints, want)
        np.testing.assert_array_equal(after.angles, joint_angles(want))
    assert out[10] is results[10]  # no pose: as it was
    assert smooth_results(results, 0.0) == results
    # Without timestamps the frames are index / fps apart.
    plain = smooth_results(_results(timestamps=False), 0.1, fps=FPS)
    for a, b in zip(plain, out, strict=True):
        np.testing.assert_array_equal(a.joints, b.joints)
    with pytest.raises(ValueError, match="'sigma' must be a non-negative"):
        smooth_results(results, float("nan"))


class _Jitter:
    """Test-only method: the reference T-pose, 1 cm of jitter per frame."""

    name = "jitter"

    def __init__(self, intrinsics, *, forest=None):
        self.rng = np.random.default_rng(3)

    def reset(self, intrinsics):
        pass

    def process(self, frame):
        body = t_pose_joints(1.75) * [1, -1, 1] + [0, 0.9, 3.0]
        joints = body + self.rng.normal(0, 0.01, body.shape)
        return FrameResult(frame.index, FrameStatus.TRACKED, joints, np.ones(15))


def test_run_methods_smooths_every_method_before_scoring():
    k = camera_preset("kinect1-qvga")
    body = t_pose_joints(1.75) * [1, -1, 1] + [0, 0.9, 3.0]
    n = 20
    frames = tuple(
        DepthFrame(np.full(k.shape, 3.0, np.float32), k, index=i, timestamp=i / FPS)
        for i in range(n)
    )
    truth = np.repeat(body[None], n, axis=0)
    seq = EvaluationSequence("toy", frames, Reference(joints=truth, angles=joint_angles(truth)))
    kw = dict(forest=object(), progress=False)
    raw = run_methods([seq], {"jitter": _Jitter}, **kw).runs[("jitter", "toy")]
    smoothed = run_methods([seq], {"jitter": _Jitter}, smooth=0.1, **kw).runs[("jitter", "toy")]
    np.testing.assert_array_equal(
        smoothed.joints, np.stack([r.joints for r in smooth_results(raw.results, 0.1)])
    )
    error = lambda j: np.linalg.norm(j - truth, axis=-1).mean()  # noqa: E731
    assert error(smoothed.joints) < 0.6 * error(raw.joints)
    # The report says so, in the JSON and under the table.
    report = evaluate([seq], {"jitter": _Jitter}, smooth=0.1, **kw)
    assert report["smoothing_s"] == 0.1
    assert "smoothed in time before scoring (--smooth 0.1 s;" in markdown_table(report, paper=False)
    lagged = evaluate([seq], {"jitter": _Jitter}, smooth=0.1, smooth_lag=0.05, **kw)
    assert lagged["smoothing_lag_s"] == 0.05
    assert "frames at most 0.05 s after each" in markdown_table(lagged, paper=False)
    assert "smoothing_s" not in evaluate([seq], {"jitter": _Jitter}, **kw)


def test_track_smooth_option_writes_smoothed_joints(tmp_path):
    from posedrift.synthetic import build_sequence, procedural_motion

    seq = build_sequence(procedural_motion(), n_frames=10, name="short")
    (tmp_path / "rec").mkdir()
    for frame in seq.frames:
        mm = np.round(frame.depth * 1000).astype(np.uint16)
        iio.imwrite(tmp_path / "rec" / f"{frame.index:06d}.png", mm)
    outs = {}
    for name, extra in (("raw", []), ("smooth", ["--smooth", "0.1"])):
        result = CliRunner().invoke(
            app,
            ["-q", "track", str(tmp_path / "rec"), "--out", str(tmp_path / name)]
            + ["--no-video", "--no-viewer"]
            + extra,
        )
        assert result.exit_code == 0, result.output
        data = json.loads((tmp_path / name / "poses.json").read_text())
        outs[name] = np.array([f["joints"] for f in data["frames"]], dtype=float)
        smoothed = {"sigma_s": 0.1, "lag_s": None} if extra else None
        assert data["smoothing"] == smoothed  # the outputs say how they were made
    want = smooth_joints(outs["raw"], np.arange(10) / 30.0, 0.1)
    np.testing.assert_allclose(outs["smooth"], want, atol=1e-9)
    assert not np.allclose(outs["smooth"], outs["raw"])


def test_lag_limits_the_frames_after_each_one():
    _, noisy, t = _swing(noise=0.01)
    full = smooth_joints(noisy, t, 0.1)
    np.testing.assert_array_equal(smooth_joints(noisy, t, 0.1, lag=0.3), full)  # 3 sigma
    # With lag 0 only the past counts: changing the future changes nothing before it.
    past = smooth_joints(noisy, t, 0.1, lag=0.0)
    changed = noisy.copy()
    changed[50:] += 0.5
    np.testing.assert_array_equal(smooth_joints(changed, t, 0.1, lag=0.0)[:50], past[:50])
    # With two frames' lag, frame k depends on frames up to k + 2 only.
    two = smooth_joints(changed, t, 0.1, lag=2 / FPS)
    np.testing.assert_array_equal(two[:48], smooth_joints(noisy, t, 0.1, lag=2 / FPS)[:48])
    assert not np.array_equal(two[48], smooth_joints(noisy, t, 0.1, lag=2 / FPS)[48])
    with pytest.raises(ValueError, match="'lag' must be a non-negative"):
        smooth_joints(noisy, t, 0.1, lag=-1.0)


@pytest.mark.parametrize("timestamps", [True, False])
def test_live_smoother_gives_the_recordings_results_with_its_latency(timestamps):
    results = _results(timestamps=timestamps)
    batch = smooth_results(results, 0.1, lag=2 / FPS)
    smoother = LiveSmoother(sigma=0.1, lag=2 / FPS)
    given = []
    for k, result in enumerate(results):
        given += smoother.push(result)
        assert [r.index for r in given] == list(range(max(0, k - 1)))  # two frames late
    given += smoother.flush()
    assert len(given) == len(results)
    for live, whole in zip(given, batch, strict=True):
        assert (live.index, live.status) == (whole.index, whole.status)
        np.testing.assert_allclose(live.joints, whole.joints, atol=1e-12)
    # Out of time order: a clear error.
    smoother.push(results[5])
    with pytest.raises(ValueError, match="frame 4 is at .* before the last frame"):
        smoother.push(results[4])


def test_smooth_lag_needs_smooth():
    result = CliRunner().invoke(app, ["track", "x", "--out", "o", "--smooth-lag", "0.1"])
    assert result.exit_code == 2
    assert "--smooth-lag needs --smooth" in result.output
