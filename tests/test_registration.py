"""Coherent Point Drift: ground truth, invariances, peers, edge cases and bad input."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from posedrift.points import sample_humanoid
from posedrift.registration import (
    ConvergenceWarning,
    CPDResult,
    _cpd,
    _estep,
    register_affine,
    register_nonrigid,
    register_rigid,
)
from posedrift.skeleton import t_pose_joints


def _rot(axis, deg):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    a = np.radians(deg)
    return np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * (k @ k)


def _rms(a, b):
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


@pytest.fixture(scope="module")
def body():
    """300 points on a 1.75 m humanoid, metres."""
    return sample_humanoid(t_pose_joints(1.75), 300, rng=1)


def _smooth_warp(src):
    """A smooth known warp: 8 degree turn, a 3 cm sinusoidal field, a 2 cm shift."""
    field = 0.03 * np.sin(2 * np.pi * src[:, [1, 2, 0]] / 1.5)
    return src @ _rot([0, 1, 0], 8).T + field + np.array([0.02, 0.0, 0.01])


def _with_outliers(points, share, rng):
    rng = np.random.default_rng(rng)
    k = round(share * len(points) / (1 - share))
    lo, hi = points.min(axis=0) - 0.1, points.max(axis=0) + 0.1
    out = np.concatenate([points, rng.uniform(lo, hi, size=(k, points.shape[1]))])
    return out[rng.permutation(len(out))]


# --------------------------------------------------------------------------- ground truth
def test_rigid_recovers_rotation_scale_translation(body):
    rot = _rot([0.3, 1.0, 0.2], 25.0)
    t = np.array([0.12, -0.05, 0.3])
    target = 1.15 * body @ rot.T + t
    res = register_rigid(body, target)
    assert res.kind == "rigid" and res.converged
    cos = (np.trace(res.rotation.T @ rot) - 1) / 2
    assert np.degrees(np.arccos(np.clip(cos, -1, 1))) < 0.01
    assert res.scale == pytest.approx(1.15, abs=1e-5)
    np.testing.assert_allclose(res.translation, t, atol=1e-5)  # 0.01 mm
    np.testing.assert_allclose(res.moved, target, atol=1e-5)
    np.testing.assert_allclose(res.apply(body[:5]), target[:5], atol=1e-5)


def test_rigid_without_scale_keeps_unit_scale(body):
    target = body @ _rot([0, 0, 1], 10).T
    res = register_rigid(body, target, scale=False)
    assert res.scale == 1.0
    np.testing.assert_allclose(res.moved, target, atol=1e-5)


def test_affine_recovers_matrix(body):
    b = np.array([[1.1, 0.05, 0.0], [0.0, 0.95, 0.1], [0.02, 0.0, 1.05]])
    t = np.array([0.1, 0.2, -0.1])
    res = register_affine(body, body @ b.T + t)
    np.testing.assert_allclose(res.matrix, b, atol=1e-5)
    np.testing.assert_allclose(res.translation, t, atol=1e-5)


def test_nonrigid_recovers_smooth_warp_of_humanoid(body):
    target = _smooth_warp(body)
    assert _rms(body, target) > 0.03  # the motion is several centimetres
    res = register_nonrigid(body, target, outlier_weight=0.0)
    assert res.kind == "nonrigid" and res.converged
    assert _rms(res.moved, target) < 1e-4  # 0.1 mm
    assert np.abs(res.moved - target).max() < 5e-4
    np.testing.assert_allclose(res.apply(body), res.moved, atol=1e-9)


def test_nonrigid_with_20_percent_outliers(body):
    truth = _smooth_warp(body)
    target = _with_outliers(truth, 0.2, rng=3)
    res = register_nonrigid(body, target, outlier_weight=0.2)
    assert _rms(res.moved, truth) < 2e-3  # 2 mm
    # the outlier model matters: without it the fit is pulled towards the outliers
    plain = register_nonrigid(body, target, outlier_weight=0.0)
    assert _rms(plain.moved, truth) > 5 * _rms(res.moved, truth)


def test_rigid_with_20_percent_outliers(body):
    rot = _rot([1, 1, 0], 15)
    truth = body @ rot.T + [0.05, 0.0, 0.0]
    res = register_rigid(body, _with_outliers(truth, 0.2, rng=4), outlier_weight=0.2)
    assert _rms(res.moved, truth) < 2e-3


@pytest.mark.parametrize("register", [register_rigid, register_affine, register_nonrigid])
def test_identity_gives_no_motion(body, register):
    res = register(body, body)
    assert res.converged
    np.testing.assert_allclose(res.moved, body, atol=1e-6)  # 1 micrometre
    assert res.sigma2 < 1e-8


EXACT = {"low_rank": None, "accelerate": False}  # step-for-step CPD, not the defaults


@pytest.mark.parametrize(
    ("register", "options"),
    [(register_rigid, {}), (register_affine, {}), (register_nonrigid, EXACT)],
)
def test_scaling_both_sets_by_1000_changes_nothing(body, register, options):
    target = _smooth_warp(body)[::-1]
    a = register(body, target, **options)
    b = register(1000 * body, 1000 * target, **options)
    assert a.iterations == b.iterations
    np.testing.assert_allclose(b.moved / 1000, a.moved, atol=1e-9)
    assert b.sigma2 / 1e6 == pytest.approx(a.sigma2, rel=1e-6)


def test_scaling_with_the_default_fast_path(body):
    # the defaults (low-rank factor, SQUAREM, exact polish) agree across units to far
    # below tol, on noisy data (no polish) and noise-free data (polished)
    truth, noisy = _noisy_problem(body)
    for target in (noisy, truth[::-1]):
        a = register_nonrigid(body, target)
        b = register_nonrigid(1000 * body, 1000 * target)
        assert a.iterations == b.iterations
        np.testing.assert_allclose(b.moved / 1000, a.moved, atol=1e-7)


def test_correspondence_and_label_transfer(body):
    target = _smooth_warp(body)[::-1]  # reversed order: the answer is a permutation
    res = register_nonrigid(body, target)
    idx, prob = res.correspondence()
    assert idx.shape == (len(target),) and prob.shape == (len(target),)
    np.testing.assert_array_equal(idx, np.arange(len(body))[::-1])
    assert np.all((prob > 0.5) & (prob <= 1.0))
    labels = np.arange(len(body)) % 15
    mass = res.transfer_labels(labels, 15)
    assert mass.shape == (len(target), 15)
    assert np.all(mass >= 0) and np.all(mass.sum(axis=1) <= 1 + 1e-12)
    np.testing.assert_array_equal(mass.argmax(axis=1), labels[::-1])
    with pytest.raises(ValueError, match="'labels'.*lie in"):
        res.transfer_labels(labels + 1, 15)
    with pytest.raises(ValueError, match="'labels'.*shape"):
        res.transfer_labels(labels[:-1], 15)
    with pytest.raises(ValueError, match="'n_labels'"):
        res.transfer_labels(labels, 0)


def test_warm_start_cuts_iterations_at_equal_accuracy(body):
    rng = np.random.default_rng(11)
    target = _smooth_warp(body) + rng.normal(scale=0.002, size=body.shape)  # 2 mm noise
    moved_on = target + 0.01 * np.sin(2 * np.pi * target[:, [2, 0, 1]])  # a further 1 cm move
    nxt = moved_on + rng.normal(scale=0.002, size=body.shape)
    first = register_nonrigid(body, target)
    cold = register_nonrigid(target, nxt)
    warm = register_nonrigid(target, nxt, warm_start=first)
    assert warm.iterations < cold.iterations
    assert _rms(warm.moved, moved_on) < 3e-3 and _rms(cold.moved, moved_on) < 3e-3
    assert _rms(warm.moved, moved_on) < 1.1 * _rms(cold.moved, moved_on)
    rigid_prev = register_rigid(body, target)
    rigid = register_rigid(body, target, warm_start=rigid_prev)
    assert rigid.iterations <= 3


def test_low_rank_and_float32_match_exact(body):
    noise = np.random.default_rng(6).normal(scale=0.001, size=body.shape)  # 1 mm
    target = _with_outliers(_smooth_warp(body) + noise, 0.1, rng=5)
    exact = register_nonrigid(body, target, **EXACT)
    low = register_nonrigid(body, target, low_rank=80, accelerate=False)
    single = register_nonrigid(body, target, dtype=np.float32, **EXACT)
    fast = register_nonrigid(body, target)  # the defaults
    fast32 = register_nonrigid(body, target, dtype=np.float32)
    assert _rms(low.moved, exact.moved) < 5e-4
    assert _rms(single.moved, exact.moved) < 5e-4
    assert _rms(fast.moved, exact.moved) < 5e-5  # 0.05 mm
    assert _rms(fast32.moved, fast.moved) < 5e-5
    assert low.kind == "nonrigid"
    np.testing.assert_allclose(low.apply(body), low.moved, atol=2e-3)


def test_max_iter_warns_and_flags(body):
    with pytest.warns(ConvergenceWarning, match="max_iter=2"):
        res = register_nonrigid(body, _smooth_warp(body), max_iter=2)
    assert not res.converged and res.iterations == 2
    assert issubclass(ConvergenceWarning, RuntimeWarning)


# --------------------------------------------------------------------------- pycpd agreement
@pytest.fixture(scope="module")
def small_pair():
    src = sample_humanoid(t_pose_joints(1.75), 120, rng=7)
    noise = np.random.default_rng(9).normal(scale=0.003, size=src.shape)  # 3 mm
    tgt = _with_outliers(_smooth_warp(src) + noise, 0.1, rng=8)
    return src, tgt


@pytest.mark.parametrize("compiled", [False, True])
def test_agrees_with_pycpd_nonrigid(small_pair, compiled):
    pycpd = pytest.importorskip("pycpd")
    src, tgt = small_pair
    reg = pycpd.DeformableRegistration(
        X=tgt, Y=src, alpha=2.0, beta=0.5, w=0.1, tolerance=0.0, max_iterations=25
    )
    moved, _ = reg.register()
    with pytest.warns(ConvergenceWarning):
        res = register_nonrigid(
            src,
            tgt,
            kernel_width=0.5,
            smoothness=2.0,
            outlier_weight=0.1,
            tol=0.0,
            max_iter=25,
            normalize=False,
            compiled=compiled,
            **EXACT,
        )
    np.testing.assert_allclose(res.moved, moved, atol=1e-8, rtol=0)
    assert res.sigma2 == pytest.approx(reg.sigma2, rel=1e-8)


def test_agrees_with_pycpd_rigid_and_affine(small_pair):
    pycpd = pytest.importorskip("pycpd")
    src, tgt = small_pair
    tgt = tgt @ _rot([0, 1, 0], 20).T
    reg = pycpd.RigidRegistration(X=tgt, Y=src, w=0.1, tolerance=0.0, max_iterations=30)
    moved, (s, _r, _t) = reg.register()
    with pytest.warns(ConvergenceWarning):
        res = register_rigid(src, tgt, outlier_weight=0.1, tol=0.0, max_iter=30, normalize=False)
    np.testing.assert_allclose(res.moved, moved, atol=1e-8, rtol=0)
    assert res.scale == pytest.approx(s, rel=1e-8)
    reg = pycpd.AffineRegistration(X=tgt, Y=src, w=0.1, tolerance=0.0, max_iterations=30)
    moved, _ = reg.register()
    with pytest.warns(ConvergenceWarning):
        res = register_affine(src, tgt, outlier_weight=0.1, tol=0.0, max_iter=30, normalize=False)
    np.testing.assert_allclose(res.moved, moved, atol=1e-8, rtol=0)


# --------------------------------------------------------------------------- kernels
@pytest.mark.skipif(not _estep.has_compiled_kernel(), reason="compiled E-step not built")
@pytest.mark.parametrize("d", [2, 3, 4])
def test_compiled_estep_matches_numpy_twin(d):
    rng = np.random.default_rng(d)
    x = rng.normal(size=(210, d))
    t = rng.normal(size=(190, d))
    for sigma2, c in [(1.0, 0.0), (0.05, 0.01), (1e-3, 1e-6)]:
        ref = _estep.estep_numpy(x, t, sigma2, c)
        for eps in (0.0, 1e-12):
            got = _estep.estep(x, t, sigma2, c, truncate_eps=eps)
            for a, b in zip(got[:3], ref[:3], strict=True):
                np.testing.assert_allclose(a, b, atol=1e-10, rtol=1e-10)
            assert got[3] == pytest.approx(ref[3], rel=1e-12, abs=1e-9)
        # float32 kernel against the float32 NumPy twin (float32 rounding: ~1e-6)
        ref32 = _estep.estep_numpy(x.astype(np.float32), t.astype(np.float32), sigma2, c)
        got32 = _estep.estep_stats(x, t, sigma2, c, single=True, truncate_eps=1e-7)
        for a, b in zip(got32[:3], ref32[:3], strict=True):
            np.testing.assert_allclose(a, b, atol=2e-5 * max(1.0, np.abs(b).max()), rtol=1e-4)
        assert got32[3] == pytest.approx(ref32[3], rel=1e-5, abs=1e-3)


@pytest.mark.skipif(not _estep.has_compiled_kernel(), reason="compiled E-step not built")
def test_compiled_estep_sums_and_kept_sort_order():
    rng = np.random.default_rng(5)
    x, t = rng.normal(size=(300, 3)), rng.normal(size=(250, 3))
    ref = _estep.estep_numpy(x, t, 0.01, 1e-4)
    order = np.arange(250, dtype=np.int64)
    target_order = np.arange(300, dtype=np.int64)
    for move in (0.0, 0.002, 0.004):  # a moving source re-sorts from the kept order
        moved = t + move * np.sin(7 * t)
        fresh = _estep.estep_numpy(x, moved, 0.01, 1e-4)
        for tord in (None, target_order):  # binary search, or a window sliding over x
            got = _estep.estep_stats(
                x, moved, 0.01, 1e-4, truncate_eps=1e-12, order=order, target_order=tord
            )
            for a, b in zip(got[:3], fresh[:3], strict=True):
                np.testing.assert_allclose(a, b, atol=1e-10)
        axis = np.argmax(np.ptp(moved, axis=0))
        assert np.array_equal(np.sort(order), np.arange(250))  # still a permutation
        assert np.all(np.diff(moved[order, axis]) >= 0)
        assert np.all(np.diff(x[target_order, axis]) >= 0)
    got = _estep.estep_stats(x, t, 0.01, 1e-4, truncate_eps=1e-12, order=np.zeros(250, int))
    np.testing.assert_allclose(got[2], ref[2], atol=1e-10)  # a non-permutation is reset
    assert got[4] == pytest.approx(ref[0].sum(), rel=1e-12)  # sum P1
    assert got[5] == pytest.approx(ref[1] @ np.sum(x * x, axis=1), rel=1e-12)  # Pt1 . |x|^2
    with pytest.raises(ValueError, match="buffer 'order'"):
        _estep._cestep.estep(x, t, 300, 250, 3, 0.01, 1e-4, 0.0, False, *got[:3], order[:5])


@pytest.mark.skipif(not _estep.has_compiled_kernel(), reason="compiled E-step not built")
@pytest.mark.parametrize("d", [2, 3, 4])
def test_compiled_label_mass_matches_numpy_twin(d):
    rng = np.random.default_rng(d)
    x = rng.normal(size=(210, d))
    t = rng.normal(size=(190, d))
    labels = rng.integers(0, 15, 190)
    labels[labels == 7] = 6  # a label no source point carries
    for sigma2, c in [(1.0, 0.0), (0.05, 0.01), (1e-3, 1e-6)]:
        ref = _estep.posterior_label_mass(x, t, sigma2, c, labels, 15, compiled=False)
        got = _estep.posterior_label_mass(x, t, sigma2, c, labels, 15)
        np.testing.assert_allclose(got, ref, atol=1e-12, rtol=1e-10)
        assert np.all(got[:, 7] == 0)
    # identity: each point's own label takes nearly all of its mass
    own = _estep.posterior_label_mass(t, t, 1e-6, 0.0, labels, 15)
    np.testing.assert_allclose(own[np.arange(190), labels], 1.0, atol=1e-9)
    # far from every source point with no outlier term: exponents clamped, never NaN
    far = _estep.posterior_label_mass(x + 1e3, t, 1e-3, 0.0, labels, 15)
    twin = _estep.posterior_label_mass(x + 1e3, t, 1e-3, 0.0, labels, 15, compiled=False)
    np.testing.assert_allclose(far, twin, rtol=1e-12)
    np.testing.assert_allclose(far.sum(axis=1), 1.0)
    # Truncated to the points within the half-width along the longest axis: every entry
    # within eps of the exact twin's, and nothing left out where there is no outlier term.
    stretched = t * np.linspace(3.0, 0.5, d)
    for sigma2, c in [(0.05, 0.01), (1e-3, 1e-6), (0.5, 0.3)]:
        # the window is narrower than the points' spread: some terms are left out
        assert 2 * _estep.truncation_halfwidth(sigma2, c, 1e-9) < np.ptp(stretched[:, 0])
        ref = _estep.posterior_label_mass(x, stretched, sigma2, c, labels, 15, compiled=False)
        got = _estep.posterior_label_mass(x, stretched, sigma2, c, labels, 15, truncate_eps=1e-9)
        assert np.abs(got - ref).max() < 1e-9
    ref = _estep.posterior_label_mass(x, t, 0.05, 0.0, labels, 15)
    assert np.array_equal(
        _estep.posterior_label_mass(x, t, 0.05, 0.0, labels, 15, truncate_eps=1e-9), ref
    )
    with pytest.raises(ValueError, match="0 <= axis < d"):
        _estep._cestep.label_mass(
            x, t, 210, 190, d, 1.0, 0.1, labels, 15, np.empty((210, 15)), d, 0.1
        )
    with pytest.raises(ValueError, match=r"labels must lie in \[0, 15\)"):
        _estep._cestep.label_mass(x, t, 210, 190, d, 1.0, 0.0, labels + 1, 15, np.empty((210, 15)))
    with pytest.raises(ValueError, match="buffer 'out'"):
        _estep._cestep.label_mass(x, t, 210, 190, d, 1.0, 0.0, labels, 15, np.empty((210, 14)))


@pytest.mark.skipif(not _estep.has_compiled_kernel(), reason="compiled E-step not built")
@pytest.mark.parametrize("d", [1, 3, 5])
def test_compiled_gaussian_kernel_matches_numpy(d):
    from posedrift.registration import _cpd

    rng = np.random.default_rng(d)
    a, b = rng.normal(size=(130, d)), rng.normal(size=(70, d))
    for beta in (0.05, 0.7, 3.0):
        got = _cpd.gaussian_kernel(a, b, beta)
        ref = _cpd.gaussian_kernel(a, b, beta, compiled=False)
        # Both exponentials are good to a few ulps times the exponent; NumPy's expanded
        # |a|^2 + |b|^2 - 2 a.b also rounds by an ulp of |a|^2 + |b|^2 (over 2 beta^2)
        scale = 2 * beta**2
        exponent = ((a[:, None] - b[None]) ** 2).sum(-1) / scale
        norms = ((a**2).sum(1)[:, None] + (b**2).sum(1)[None]) / scale
        bound = 4e-15 * (1 + exponent) + 1e-15 * norms
        kept = exponent < 690  # beyond, the kernel clamps at exp(-700); both are ~0
        assert (np.abs(got[kept] / ref[kept] - 1) <= bound[kept]).all()
        assert (got[~kept] < 1e-299).all() and (ref[~kept] < 1e-299).all()
    # identity: a point's kernel with itself is 1; far points are (clamped) zero
    assert np.array_equal(np.diag(_cpd.gaussian_kernel(a, a, 0.5)), np.ones(130))
    assert _cpd.gaussian_kernel(a, a + 1e3, 0.5).max() < 1e-300
    assert _cpd.gaussian_kernel(a[:0], b, 1.0).shape == (0, 70)


def test_numpy_estep_blocks_agree(monkeypatch):
    rng = np.random.default_rng(0)
    x, t = rng.normal(size=(300, 3)), rng.normal(size=(50, 3))
    whole = _estep.estep_numpy(x, t, 0.3, 0.01)
    monkeypatch.setattr(_estep, "_BLOCK_ELEMENTS", 1000)  # 20 target points per block
    blocked = _estep.estep_numpy(x, t, 0.3, 0.01)
    for a, b in zip(whole[:3], blocked[:3], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-14)


# --------------------------------------------------------------------------- edge cases
@pytest.mark.parametrize("register", [register_rigid, register_affine, register_nonrigid])
def test_one_point_each(register):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        res = register([[0.0, 0.0, 0.0]], [[0.1, 0.2, 0.3]])
    assert np.all(np.isfinite(res.moved)) and res.moved.shape == (1, 3)
    # affine too: one source point has no spread, so B = I and only t is fitted
    np.testing.assert_allclose(res.moved, [[0.1, 0.2, 0.3]], atol=1e-3)


@pytest.mark.parametrize("register", [register_rigid, register_affine, register_nonrigid])
def test_coincident_points(register):
    same = np.ones((20, 3))
    res = register(same, same)
    assert np.all(np.isfinite(res.moved)) and np.isfinite(res.sigma2)
    np.testing.assert_allclose(res.moved, same, atol=1e-9)
    # duplicated source points onto a spread target: finite, no NaN
    rng = np.random.default_rng(0)
    src = np.repeat(rng.normal(size=(10, 3)), 3, axis=0)
    res = register(src, src[::3] + 0.01)
    assert np.all(np.isfinite(res.moved))


_ONE_SRC = np.array([[0.10, -0.60, 2.80]])  # metres, 2.8 m in front of the camera
_ONE_TGT = np.array([[0.11, -0.62, 2.79]])  # 24.5 mm from the source point
_REGISTERS = [
    pytest.param(register_nonrigid, {}, id="nonrigid"),
    pytest.param(register_nonrigid, {"low_rank": None, "accelerate": False}, id="exact"),
    pytest.param(register_rigid, {}, id="rigid"),
    pytest.param(register_affine, {}, id="affine"),
]


def _in_metres_and_millimetres(register, source, target, options):
    """Both runs (metres, millimetres): the same to a nanometre (0.1 um for the fast
    nonrigid defaults, as in test_scaling_with_the_default_fast_path; 10 nm for the exact
    nonrigid solve, whose rounding depends on the BLAS kernels: OpenBLAS's SkylakeX ones,
    picked on Intel AVX-512 processors, put a body shrunk onto one point 1.08 nm apart in
    the two units, its Haswell ones 0.67 nm), same iterations."""
    m = register(source, target, **options)
    mm = register(source * 1000, target * 1000, **options)
    assert mm.iterations == m.iterations and mm.converged == m.converged
    nonrigid = register is register_nonrigid
    fast = nonrigid and options.get("low_rank", "auto") == "auto"
    atol = 1e-7 if fast else 1e-8 if nonrigid else 1e-9
    np.testing.assert_allclose(mm.moved / 1000, m.moved, rtol=0, atol=atol)
    assert mm.sigma2 / 1e6 == pytest.approx(m.sigma2, rel=1e-6)
    if m.matrix is not None:
        np.testing.assert_allclose(mm.matrix, m.matrix, rtol=0, atol=1e-9)
        np.testing.assert_allclose(mm.translation / 1000, m.translation, rtol=0, atol=1e-9)
    return m


@pytest.mark.parametrize("case", ["one", "twenty", "jittered"])
@pytest.mark.parametrize(("register", "options"), _REGISTERS)
def test_single_point_sets_land_on_the_target_in_any_unit(register, options, case):
    # the target has no spread: exactly 0 (one point), rounding of its mean (copies),
    # or a picometre of jitter at 2.8 m; the source is one point too (a translation)
    count = {"one": 1, "twenty": 20, "jittered": 50}[case]
    src, tgt = np.repeat(_ONE_SRC, count, axis=0), np.repeat(_ONE_TGT, count, axis=0)
    if case == "jittered":
        rng = np.random.default_rng(0)
        src, tgt = src + rng.normal(0, 1e-12, src.shape), tgt + rng.normal(0, 1e-12, tgt.shape)
    res = _in_metres_and_millimetres(register, src, tgt, options)  # warnings are errors
    assert res.converged and res.iterations < 20
    assert np.abs(res.moved - _ONE_TGT).max() < 1e-6  # on the target to a micrometre
    assert res.sigma2 < 1e-10  # below (10 um)^2
    if res.matrix is not None:  # a single source point: no rotation, scale or shear
        np.testing.assert_allclose(res.matrix, np.eye(3), rtol=0, atol=1e-12)
        np.testing.assert_allclose(res.translation, (_ONE_TGT - _ONE_SRC)[0], rtol=0, atol=1e-9)


@pytest.mark.parametrize(("register", "options"), _REGISTERS)
def test_one_sided_single_points_do_not_depend_on_units(register, options, body):
    # a whole body onto 30 copies of one point, and 30 copies of one point onto a body
    many_to_one = _in_metres_and_millimetres(
        register, body, np.repeat(_ONE_TGT, 30, axis=0), options
    )
    if register is not register_nonrigid:  # the linear fits shrink the body onto it
        assert np.abs(many_to_one.moved - _ONE_TGT).max() < 1e-6
        np.testing.assert_allclose(many_to_one.matrix, 0.0, atol=1e-12)
    one_to_many = _in_metres_and_millimetres(
        register, np.repeat(_ONE_SRC, 30, axis=0), body, {**options, "outlier_weight": 0.0}
    )
    # without outliers the single source point lands at the body's centroid (with the
    # default w = 0.1 the far points weigh less), with an identity matrix; nonrigid
    # stops 6 mm short of its 1.6 m move (the regularizer lambda sigma^2 |W|^2)
    tol = 0.01 if register is register_nonrigid else 1e-6
    assert np.abs(one_to_many.moved - body.mean(axis=0)).max() < tol
    if one_to_many.matrix is not None:
        np.testing.assert_allclose(one_to_many.matrix, np.eye(3), rtol=0, atol=1e-12)


def test_affine_with_a_planar_source_in_any_unit():
    # every source point at z = 2.8 m: B's z column is undetermined (the system is
    # singular); it must stay the identity's, not blow up (it was 1e17 and 4.8 m off)
    rng = np.random.default_rng(0)
    src = np.column_stack([rng.uniform(-0.3, 0.3, 60), rng.uniform(-0.8, 0.8, 60)])
    src = np.column_stack([src, np.full(60, 2.8)])
    b = np.array([[1.1, 0.1, 0.0], [-0.05, 0.95, 0.0], [0.0, 0.0, 1.0]])
    shift = np.array([0.02, -0.01, 0.03])
    res = _in_metres_and_millimetres(register_affine, src, src @ b.T + shift, {})
    assert np.abs(res.moved - (src @ b.T + shift)).max() < 1e-6
    np.testing.assert_allclose(res.matrix, b, rtol=0, atol=1e-6)
    off_plane = np.array([[0.1, 0.2, 2.9], [-0.2, 0.5, 2.6]])  # 10-20 cm off the plane
    assert np.abs(res.apply(off_plane) - (off_plane @ b.T + shift)).max() < 1e-6


@pytest.mark.parametrize("register", [register_rigid, register_affine, register_nonrigid])
def test_bad_input(register, body):
    name = register.__name__
    with pytest.raises(ValueError, match=rf"'source' argument of {name}.*at least 1"):
        register(np.empty((0, 3)), body)
    with pytest.raises(ValueError, match="'target'.*at least 1"):
        register(body, np.empty((0, 3)))
    bad = body.copy()
    bad[3, 1] = np.nan
    with pytest.raises(ValueError, match="'target'.*finite"):
        register(body, bad)
    with pytest.raises(ValueError, match="'source'.*finite"):
        register(np.where(bad == bad, bad, np.inf), body)
    with pytest.raises(ValueError, match="'source'.*2-D"):
        register(body.ravel(), body)
    with pytest.raises(ValueError, match="same number of columns"):
        register(body, body[:, :2])
    with pytest.raises(ValueError, match=r"'outlier_weight'.*\[0, 1\)"):
        register(body, body, outlier_weight=1.0)
    with pytest.raises(ValueError, match="'tol'"):
        register(body, body, tol=-1.0)
    with pytest.raises(ValueError, match="'max_iter'.*int"):
        register(body, body, max_iter=2.5)
    with pytest.raises(ValueError, match="'dtype'"):
        register(body, body, dtype=np.int32)
    with pytest.raises(ValueError, match="'warm_start'.*CPDResult"):
        register(body, body, warm_start="previous")
    with pytest.raises(ValueError, match="'source'.*numeric"):
        register([["a", "b", "c"]], body)


def test_bad_nonrigid_parameters(body):
    with pytest.raises(ValueError, match=r"'kernel_width' parameter of register_nonrigid.*-1"):
        register_nonrigid(body, body, kernel_width=-1)
    with pytest.raises(ValueError, match="'smoothness'"):
        register_nonrigid(body, body, smoothness=0.0)
    with pytest.raises(ValueError, match="'low_rank'"):
        register_nonrigid(body, body, low_rank=0)
    res2d = register_rigid(body[:, :2], body[:, :2])
    with pytest.raises(ValueError, match="'warm_start'.*2-D"):
        register_nonrigid(body, body, warm_start=res2d)
    res = register_nonrigid(body, body)
    with pytest.raises(ValueError, match="'points' argument of apply.*3 columns"):
        res.apply(body[:, :2])
    assert isinstance(res, CPDResult)


def test_result_is_frozen(body):
    res = register_rigid(body, body)
    with pytest.raises(AttributeError):
        res.sigma2 = 1.0  # type: ignore[misc]


def test_works_without_the_compiled_extension(body, monkeypatch):
    target = _smooth_warp(body)
    _, noisy = _noisy_problem(body)
    with_ext = register_nonrigid(body, target, **EXACT)
    fast = [register_nonrigid(body, t) for t in (target, noisy)]  # defaults: C M-step too
    monkeypatch.setattr(_estep, "_cestep", None)
    assert not _estep.has_compiled_kernel()
    without = register_nonrigid(body, target, **EXACT)
    np.testing.assert_allclose(without.moved, with_ext.moved, atol=1e-9)
    for res, t in zip(fast, (target, noisy), strict=True):
        twin = register_nonrigid(body, t)
        assert twin.iterations == res.iterations
        np.testing.assert_allclose(twin.moved, res.moved, atol=1e-8)


# --------------------------------------------------------------------------- fast paths
def _noisy_problem(body, seed=21):
    rng = np.random.default_rng(seed)
    truth = _smooth_warp(body)
    return truth, _with_outliers(truth + rng.normal(scale=0.002, size=body.shape), 0.1, rng=seed)


def test_accelerated_em_matches_plain_em_in_fewer_iterations(body):
    truth, target = _noisy_problem(body)
    plain = register_nonrigid(body, target, tol=1e-8, max_iter=400, **EXACT)
    fast = register_nonrigid(body, target, tol=1e-8, max_iter=400, low_rank=None)
    assert fast.converged and plain.converged
    assert fast.iterations < 0.8 * plain.iterations
    assert _rms(fast.moved, plain.moved) < 1e-5  # 0.01 mm: the same fixed point
    assert fast.objective <= plain.objective + 1e-6 * abs(plain.objective)
    assert fast.sigma2 == pytest.approx(plain.sigma2, rel=1e-3)
    # at the default tolerance both stop within 0.1 mm of each other and of the truth
    a = register_nonrigid(body, target, **EXACT)
    b = register_nonrigid(body, target, low_rank=None, accelerate=True)
    assert _rms(a.moved, b.moved) < 1e-4 and _rms(b.moved, truth) < 2e-3
    np.testing.assert_allclose(b.apply(body), b.moved, atol=1e-9)
    # warm start and acceleration together
    warm = register_nonrigid(body, target, low_rank=None, accelerate=True, warm_start=a)
    assert _rms(warm.moved, truth) < 2e-3


def test_accelerated_em_max_iter_counts_m_steps(body):
    with pytest.warns(ConvergenceWarning, match="max_iter=5"):
        res = register_nonrigid(body, _smooth_warp(body), max_iter=5, accelerate=True)
    assert res.iterations == 5 and not res.converged


@pytest.mark.parametrize(
    "options",
    [{}, {"accelerate": False}, {"dtype": np.float32}, {"max_iter": 5}, {"outlier_weight": 0.0}],
)
def test_compiled_loop_takes_the_python_loops_steps(body, options, monkeypatch):
    if not _estep.has_compiled_kernel():
        pytest.skip("the compiled kernels are not built (no C compiler at install)")
    truth, target = _noisy_problem(body)
    runs = {}
    for compiled_loop in (True, False):
        monkeypatch.setattr(_cpd, "_COMPILED_LOOP", compiled_loop)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            first = register_nonrigid(body, target, low_rank=24, **options)
            warm = register_nonrigid(body, truth, low_rank=24, warm_start=first, **options)
        runs[compiled_loop] = (first, warm)
    for fused, loop in zip(runs[True], runs[False], strict=True):
        assert (fused.iterations, fused.converged) == (loop.iterations, loop.converged)
        # The same steps; only the sums round differently: a nanometre at most.
        np.testing.assert_allclose(fused.moved, loop.moved, rtol=0, atol=1e-9)
        np.testing.assert_allclose(fused.apply(truth), loop.apply(truth), rtol=0, atol=1e-9)
        assert fused.sigma2 == pytest.approx(loop.sigma2, rel=1e-6)
        assert fused.objective == pytest.approx(loop.objective, rel=1e-9)
    if not options:  # the defaults fit the noisy target within 3 mm
        assert _rms(runs[True][0].moved, truth) < 3e-3


def test_compiled_loop_hands_a_failed_cholesky_back():
    if not _estep.has_compiled_kernel():
        pytest.skip("the compiled kernels are not built (no C compiler at install)")
    pts = np.random.default_rng(2).normal(size=(40, 3))
    order = np.arange(40, dtype=np.int64)
    factor = np.zeros((4, 40))
    factor[0] = 0.5  # three zero rows and no regularizer left: a singular M-step system
    args = (pts, pts, factor, 1, 0.1, 5e-324, 1e-10, 1e-3, False, 1e-5, 10, True, order, order)
    assert _cpd._compiled_loop(*args) is None
    with pytest.raises(ValueError, match="em_lowrank: need"):
        _estep._cestep.em_lowrank(
            pts, pts, factor[:3], 40, 40, 3, 3, 0.1, 1.0, 1e-10, 1e-12, 1e-3, False, 1e-5, 10,
            True, order, order, np.empty((3, 3)), np.empty((40, 3)),
        )  # fmt: skip


def test_auto_polishes_noise_free_fits_with_the_exact_kernel(body):
    target = _smooth_warp(body)
    plain_factor = register_nonrigid(body, target, outlier_weight=0.0, low_rank=64)
    auto = register_nonrigid(body, target, outlier_weight=0.0)  # the defaults
    exact = register_nonrigid(body, target, outlier_weight=0.0, **EXACT)
    assert _rms(plain_factor.moved, target) > 5e-5  # the factor alone: ~0.1 mm
    assert auto._landmarks is None and auto._coef is not None  # polished: exact W
    assert _rms(auto.moved, target) < 1e-5 and _rms(auto.moved, exact.moved) < 1e-5
    _, noisy = _noisy_problem(body)
    assert register_nonrigid(body, noisy)._landmarks is not None  # 2 mm noise: no polish


def test_auto_low_rank_picks_by_kernel_and_matches_exact(body):
    _, target = _noisy_problem(body)
    exact = register_nonrigid(body, target, low_rank=None)
    auto = register_nonrigid(body, target, low_rank="auto")
    assert auto._landmarks is not None  # kernel_width=2: the 64-landmark factor
    assert _rms(auto.moved, exact.moved) < 1e-4  # 0.1 mm
    # the low-rank field is the one fitted: apply(source) reproduces moved
    np.testing.assert_allclose(auto.apply(body), auto.moved, atol=1e-9)
    np.testing.assert_allclose(auto.apply(body + 0.01), exact.apply(body + 0.01), atol=5e-4)
    # a narrow kernel is not low rank: "auto" keeps the exact solve
    narrow = register_nonrigid(body, target, low_rank="auto", kernel_width=0.3)
    assert narrow._landmarks is None
    ref = register_nonrigid(body, target, kernel_width=0.3, low_rank=None)
    np.testing.assert_allclose(narrow.moved, ref.moved, atol=1e-12)
    small = register_nonrigid(body[:50], target, low_rank="auto")  # few points: exact
    assert small._landmarks is None
    with pytest.raises(ValueError, match="'low_rank'.*'auto'"):
        register_nonrigid(body, target, low_rank="fast")


def test_m_steps_solve_the_cpd_system():
    from posedrift.registration import _cpd

    rng = np.random.default_rng(3)
    y = rng.normal(size=(150, 3))
    g = _cpd.gaussian_kernel(y, y, 1.5)
    p1 = rng.uniform(0.0, 2.0, size=150)
    p1[:4] = 0.0  # source points with no posterior mass
    px = p1[:, None] * (y + 0.05 * rng.normal(size=y.shape))
    s2, lam = 0.02, 2.0
    work = np.full_like(g, np.nan)  # the buffer is overwritten, never read
    w = _cpd._solve_nonrigid(g, None, p1, px, y, s2, lam, work)
    # dP1 G W + lambda s2 W = P X - dP1 Y
    resid = p1[:, None] * (g @ w) + lam * s2 * w - (px - p1[:, None] * y)
    assert np.abs(resid).max() < 1e-10 * max(1.0, np.abs(px).max())
    # the Woodbury M-step with an exact factor Z Z' = G gives the same W
    ev, u = np.linalg.eigh(g)
    keep = ev > 1e-13 * ev[-1]
    z = u[:, keep] * np.sqrt(ev[keep])
    w_lr = _cpd._solve_nonrigid(None, z, p1, px, y, s2, lam)
    np.testing.assert_allclose(g @ w_lr, g @ w, atol=1e-8)
    # the loop's low-rank step returns Z' W (K' x D) of that same W
    u = _cpd._solve_low_rank(z, p1, px, y, lam * s2)
    np.testing.assert_allclose(u, z.T @ w_lr, atol=1e-8)
    if _estep.has_compiled_kernel():  # its compiled twin, on Z' padded with zero rows
        k = z.shape[1]
        zt = np.zeros((-(-k // 4) * 4, len(y)))
        zt[:k] = z.T
        u_c, moved = np.empty((zt.shape[0], 3)), np.empty_like(y)
        ok, pxm, tpt = _estep._cestep.lowrank_mstep(
            zt, len(y), zt.shape[0], 3, p1, px, y, lam * s2, u_c, moved
        )
        assert ok and np.all(u_c[k:] == 0)
        np.testing.assert_allclose(u_c[:k], u, atol=1e-8)
        np.testing.assert_allclose(moved, y + z @ u, atol=1e-10)
        assert pxm == pytest.approx(np.sum(px * moved), rel=1e-12)
        assert tpt == pytest.approx(p1 @ np.sum(moved**2, axis=1), rel=1e-12)
        with pytest.raises(ValueError, match="multiple of 4"):
            _estep._cestep.lowrank_mstep(zt, len(y), 3, 3, p1, px, y, 1.0, u_c, moved)
    # the Nyström factor of a wide kernel (landmarks numerically dependent, as
    # low_rank="auto" requires) reproduces G to 1e-4 (G's entries are in (0, 1])
    zn, land, proj, kept = _cpd.low_rank_factor(y, 5.0, 64)
    assert kept <= 0.8 * 64 and land.shape == (64, 3) and proj.shape == (64, kept)
    assert np.abs(zn @ zn.T - _cpd.gaussian_kernel(y, y, 5.0)).max() < 1e-4


@pytest.mark.parametrize(
    "options", [{"accelerate": True}, {"low_rank": "auto", "accelerate": True}]
)
def test_fast_paths_on_edge_cases(body, options):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        one = register_nonrigid([[0.0, 0.0, 0.0]], [[0.1, 0.2, 0.3]], **options)
    np.testing.assert_allclose(one.moved, [[0.1, 0.2, 0.3]], atol=1e-3)
    same = np.ones((20, 3))
    np.testing.assert_allclose(register_nonrigid(same, same, **options).moved, same, atol=1e-9)
    rng = np.random.default_rng(0)
    src = np.repeat(rng.normal(size=(40, 3)), 3, axis=0)  # duplicated source points
    assert np.all(np.isfinite(register_nonrigid(src, src[::3] + 0.01, **options).moved))
    ident = register_nonrigid(body, body, **options)
    np.testing.assert_allclose(ident.moved, body, atol=1e-6)
    no_outliers = register_nonrigid(body, _smooth_warp(body), outlier_weight=0.0, **options)
    assert _rms(no_outliers.moved, _smooth_warp(body)) < 1e-3
