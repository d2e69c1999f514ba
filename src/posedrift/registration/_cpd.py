"""Coherent Point Drift (Myronenko & Song, TPAMI 2010): rigid, affine and nonrigid.

Pure array kernels (initial sigma^2, M-steps, kernel and low-rank factorization) and
the public functions that sequence them. See METHOD.md section 3 for the choices:
closed-form initial sigma^2, the outlier constant, the symmetric Cholesky M-step,
the sigma^2 guard, stopping on the relative change of the objective, normalization.

References
----------
.. [1] A. Myronenko and X. Song, "Point Set Registration: Coherent Point Drift",
   IEEE TPAMI 32(12), 2010. doi:10.1109/TPAMI.2010.46
"""

from __future__ import annotations

import functools
import math
import warnings

import numpy as np
import scipy.linalg as sla
from scipy.linalg.lapack import dpotrf as _potrf
from scipy.linalg.lapack import dpotrs as _potrs

from posedrift._validation import check_points, check_scalar
from posedrift.registration import _estep
from posedrift.registration._result import ConvergenceWarning, CPDResult

_SIGMA2_FLOOR = 1e-10  # in normalized units (squared fractions of the target's RMS radius)
_SIGMA2_FLOOR_32 = 1e-7  # float32 E-step: distances are only good to ~1e-7 relative
_TRUNCATE_EPS = _estep.TRUNCATE_EPS  # compiled E-step: terms below this share of c dropped


# --------------------------------------------------------------------------- kernels
def initial_sigma2(target: np.ndarray, source: np.ndarray) -> float:
    """Closed-form ``sum_mn |x_n - y_m|^2 / (M N D)`` in O((M + N) D)."""
    n, d = target.shape
    m = source.shape[0]
    sx = target.sum(axis=0)
    sy = source.sum(axis=0)
    num = m * float(np.sum(target * target)) + n * float(np.sum(source * source))
    num -= 2.0 * float(sx @ sy)
    return max(num, 0.0) / (m * n * d)


def outlier_constant(sigma2: float, w: float, m: int, n: int, d: int) -> float:
    """The uniform component's term of the E-step denominator."""
    if w == 0.0:
        return 0.0
    return (2.0 * np.pi * sigma2) ** (d / 2.0) * w / (1.0 - w) * m / n


def gaussian_kernel(a: np.ndarray, b: np.ndarray, beta: float, compiled: bool = True) -> np.ndarray:
    """``exp(-|a_i - b_j|^2 / (2 beta^2))`` without an (I, J, D) temporary.

    The compiled kernel where built (its exponential vectorized, the squared
    differences summed directly), else NumPy (squared distances expanded, which rounds
    worse for large exponents); relative agreement about 1e-15 times the exponent.
    """
    kernel = getattr(_estep._cestep, "gauss", None) if compiled else None
    if kernel is not None:
        a = np.ascontiguousarray(a, dtype=np.float64)
        b = np.ascontiguousarray(b, dtype=np.float64)
        out = np.empty((a.shape[0], b.shape[0]))
        kernel(a, b, a.shape[0], b.shape[0], a.shape[1], -1.0 / (2.0 * beta * beta), out)
        return out
    d2 = np.einsum("ij,ij->i", a, a)[:, None] + np.einsum("ij,ij->i", b, b)[None, :]
    d2 -= 2.0 * (a @ b.T)
    np.maximum(d2, 0.0, out=d2)
    d2 *= -1.0 / (2.0 * beta * beta)
    return np.exp(d2, out=d2)


def low_rank_factor(
    source: np.ndarray, beta: float, rank: int, *, rcond: float = 1e-10, _landmark_eig=None
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """Nyström factor ``G ~ Z Z'`` from ``rank`` landmark source points.

    Landmarks: ``rank`` source points drawn with a fixed seed (deterministic). With
    ``W_k = U diag(e) U'`` the landmark kernel, ``Z = C P`` with ``C = G(source,
    landmarks)`` and ``P = U diag(e)^(-1/2)`` over the eigenvalues above ``rcond``
    times the largest (K' <= K), so ``Z Z'`` keeps the leading eigen-structure of G.
    O(M K) kernel values and O(M K^2 + K^3) flops; never the M x M kernel.

    Returns
    -------
    z : (M, K') float
    landmarks : (K, D) float
        The landmark points; ``gaussian_kernel(p, landmarks, beta) @ proj`` is the
        feature map of any point p (``z`` for the source itself).
    proj : (K, K') float
    kept : int
        K'. ``kept < K`` means the landmark kernel is numerically rank-deficient:
        the landmarks already span G's numerical range.
    """
    land = _landmark_indices(source.shape[0], rank)
    landmarks = source[land]
    ev, u = _landmark_eig if _landmark_eig is not None else _landmark_eigh(landmarks, beta)
    keep = ev > ev[-1] * rcond
    proj = u[:, keep] / np.sqrt(ev[keep])
    return gaussian_kernel(source, landmarks, beta) @ proj, landmarks, proj, int(keep.sum())


@functools.lru_cache(maxsize=16)
def _landmark_indices(m: int, rank: int) -> np.ndarray:
    idx = np.sort(np.random.default_rng(0).choice(m, size=min(rank, m), replace=False))
    idx.flags.writeable = False
    return idx


def _landmark_eigh(landmarks: np.ndarray, beta: float):
    return np.linalg.eigh(gaussian_kernel(landmarks, landmarks, beta))


def low_rank_kernel(source: np.ndarray, beta: float, rank: int) -> np.ndarray:
    """The factor Z (M, K') of :func:`low_rank_factor` alone."""
    return low_rank_factor(source, beta, rank)[0]


_AUTO_RANK = 64  # landmarks tried by low_rank="auto"
_AUTO_SATURATED = 0.8  # low rank when at most this share of them is numerically independent
_AUTO_EXACT_MAX = 3000  # above this, "auto" never builds the dense M x M kernel
_AUTO_POLISH = 0.01  # "auto" polishes with the exact kernel when lambda sigma2 < this * trace


def _choose_kernel(src_n: np.ndarray, beta: float, low_rank):
    """``(g, (z, landmarks, proj) or None)`` for ``low_rank`` = None, an int or "auto"."""
    m = src_n.shape[0]
    if low_rank == "auto":
        if m <= _AUTO_RANK:
            return gaussian_kernel(src_n, src_n, beta), None
        eig = _landmark_eigh(src_n[_landmark_indices(m, _AUTO_RANK)], beta)
        kept = int(np.sum(eig[0] > eig[0][-1] * 1e-10))
        saturated = kept <= _AUTO_SATURATED * _AUTO_RANK
        if saturated or m > _AUTO_EXACT_MAX:
            z, landmarks, proj, _ = low_rank_factor(src_n, beta, _AUTO_RANK, _landmark_eig=eig)
            return None, (z, landmarks, proj)
        return gaussian_kernel(src_n, src_n, beta), None
    if low_rank is None or low_rank >= m:
        return gaussian_kernel(src_n, src_n, beta), None
    z, landmarks, proj, _ = low_rank_factor(src_n, beta, low_rank)
    return None, (z, landmarks, proj)


def _solve_nonrigid(g, lowrank, p1, px, source, sigma2, smoothness, work=None):
    """Symmetric M-step: returns W with ``(G + lambda s2 dP1^-1) W = dP1^-1 P X - Y``.

    ``work``: an optional (M, M) float64 buffer for the exact solve's matrix (saves an
    allocation per iteration); overwritten.
    """
    reg = smoothness * sigma2
    if lowrank is None:
        sq = np.sqrt(p1)
        # rhs = dP1^(-1/2) (P X - dP1 Y), zero where P1 == 0 (there P X == 0 too)
        safe = np.where(sq > 0, sq, 1.0)
        rhs = px / safe[:, None] - sq[:, None] * source
        a = np.multiply(g, sq[:, None], out=work)
        a *= sq[None, :]
        a.flat[:: a.shape[0] + 1] += reg
        # LAPACK directly: the Fortran-order view of the symmetric C array is the same
        # matrix, so no copy; "upper" in Fortran order is the lower triangle here.
        chol, info = _potrf(a.T, lower=False, overwrite_a=True, clean=False)
        if info != 0:  # not positive definite in floating point: the checked path
            a = g * sq[:, None] * sq[None, :]
            a.flat[:: a.shape[0] + 1] += reg
            v = sla.cho_solve(sla.cho_factor(a, check_finite=False), rhs, check_finite=False)
        else:
            v, info = _potrs(chol, rhs, lower=False)
        return sq[:, None] * v
    z = lowrank
    b = px - p1[:, None] * source
    # Woodbury: (dP1 Z Z' + s I)^-1 = (I - dP1 Z (s I + Z' dP1 Z)^-1 Z') / s
    small = (z.T * p1) @ z  # K x K, symmetric positive definite
    small.flat[:: small.shape[0] + 1] += reg
    chol, info = _potrf(small, lower=True, overwrite_a=True, clean=False)
    if info == 0:
        inner, info = _potrs(chol, z.T @ b, lower=True)
    if info != 0:  # pragma: no cover - K x K with reg > 0 on the diagonal
        small = (z.T * p1) @ z
        small.flat[:: small.shape[0] + 1] += reg
        inner = np.linalg.lstsq(small, z.T @ b, rcond=None)[0]
    return (b - p1[:, None] * (z @ inner)) / reg


def _solve_low_rank(z, p1, px, source, reg):
    """Low-rank M-step in the factor's coordinates: ``U = Z' W`` (K' x D).

    With ``G = Z Z'``, Woodbury gives ``W = (B - dP1 Z U) / reg`` with
    ``U = (Z' dP1 Z + reg I)^-1 Z' B`` and ``B = P X - dP1 Y``; then
    ``Z' W = (Z' B - Z' dP1 Z U) / reg = U``, so ``T = Y + Z U`` and
    ``tr(W' G W) = |U|^2`` without ever forming W (M x D).
    """
    zp = z.T * p1  # (K', M)
    small = zp @ z
    small.flat[:: small.shape[0] + 1] += reg
    rhs = z.T @ px - zp @ source
    chol, info = _potrf(small, lower=True, overwrite_a=True, clean=False)
    if info == 0:
        u, info = _potrs(chol, rhs, lower=True)
        if info == 0:
            return u
    small = zp @ z  # pragma: no cover - K' x K' with reg > 0 on the diagonal
    small.flat[:: small.shape[0] + 1] += reg
    return np.linalg.lstsq(small, rhs, rcond=None)[0]


def _kernel_apply(g, lowrank, w):
    if lowrank is None:
        return g @ w
    return lowrank @ (lowrank.T @ w)


# --------------------------------------------------------------------------- validation
def _check_common(name, source, target, outlier_weight, tol, max_iter, dtype, warm_start):
    src = check_points(source, "source", dim=None, caller=name)
    tgt = check_points(target, "target", dim=None, caller=name)
    if src.shape[1] != tgt.shape[1]:
        raise ValueError(
            f"The 'source' and 'target' arguments of {name} must have the same number of "
            f"columns. Got {src.shape[1]} and {tgt.shape[1]} instead."
        )
    w = check_scalar(
        outlier_weight, "outlier_weight", low=0.0, high=1.0, include_low=True, caller=name
    )
    tol = check_scalar(tol, "tol", low=0.0, include_low=True, caller=name)
    max_iter = check_scalar(
        max_iter, "max_iter", low=1, include_low=True, integer=True, caller=name
    )
    dt = np.dtype(dtype) if dtype in (np.float32, np.float64, "float32", "float64") else None
    if dt is None:
        raise ValueError(
            f"The 'dtype' parameter of {name} must be numpy.float32 or numpy.float64. "
            f"Got {dtype!r} instead."
        )
    if warm_start is not None:
        if not isinstance(warm_start, CPDResult):
            raise ValueError(
                f"The 'warm_start' parameter of {name} must be a CPDResult or None. "
                f"Got {type(warm_start).__name__} instead."
            )
        if warm_start.moved.shape[1] != src.shape[1]:
            raise ValueError(
                f"The 'warm_start' parameter of {name} must come from {src.shape[1]}-D points. "
                f"Got a result for {warm_start.moved.shape[1]}-D points instead."
            )
    return src, tgt, w, tol, max_iter, dt


_DEGENERATE_RTOL = 1e-9  # a set whose RMS radius is below this share of its largest coordinate


def _rms_radius(points: np.ndarray, centre: np.ndarray) -> float:
    squares = points - centre
    squares *= squares
    if squares.shape[1] == 3:  # coordinate by coordinate: the same sums as below, cheaper
        return float(np.sqrt(np.mean(squares[:, 0] + squares[:, 1] + squares[:, 2])))
    return float(np.sqrt(np.mean(np.sum(squares, axis=1))))


def _magnitude(points: np.ndarray) -> float:
    return float(np.abs(points).max())


def _is_single_point(points: np.ndarray) -> bool:
    """Whether all points coincide up to rounding (relative to their coordinates)."""
    spread = _rms_radius(points, points.mean(axis=0))
    return not spread > _DEGENERATE_RTOL * _magnitude(points)


def _normalization(
    target: np.ndarray, source: np.ndarray, normalize: bool
) -> tuple[np.ndarray, float, bool, bool]:
    """One similarity for both sets, and whether each set is a single point.

    The similarity maps the target's centroid to 0 and its RMS radius to 1. A target
    whose RMS radius is at most ``_DEGENERATE_RTOL`` times its largest absolute
    coordinate (all points coincide, up to rounding) has no usable radius: the unit is
    then the RMS distance of the source points to it, or, when the source is that same
    point too, the largest absolute coordinate of either set (1 when all are 0). Every
    choice scales with the input, so results do not depend on units.

    Returns
    -------
    centre : (D,) float
    unit : float
    target_point, source_point : bool
        Whether the target (source) points all coincide up to rounding.
    """
    d = target.shape[1]
    centre = target.mean(axis=0)
    unit = _rms_radius(target, centre)
    target_point = not unit > _DEGENERATE_RTOL * _magnitude(target)
    source_point = _is_single_point(source)
    if not normalize:
        return np.zeros(d), 1.0, target_point, source_point
    if target_point:
        unit = _rms_radius(source, centre)
        magnitude = max(_magnitude(target), _magnitude(source))
        if not unit > _DEGENERATE_RTOL * magnitude:  # source and target: one point
            unit = magnitude if magnitude > 0.0 else 1.0
    if not np.isfinite(unit) or unit <= 0.0:
        unit = 1.0
    return centre, unit, target_point, source_point


def _start_sigma2(tgt_n, moved_n, warm_start, unit, floor):
    if warm_start is not None:  # a warm start's sigma^2 replaces the closed form: none needed
        return max(warm_start.sigma2 / unit**2, floor)
    return max(initial_sigma2(tgt_n, moved_n), floor)


def _finish(converged, name, iterations, tol):
    if not converged:
        warnings.warn(
            f"{name} stopped after max_iter={iterations} iterations before the relative "
            f"change of the objective fell below tol={tol:g}.",
            ConvergenceWarning,
            stacklevel=3,
        )


def _relative_change(new: float, old: float) -> float:
    return abs(new - old) / max(abs(new), 1e-300)


_COMPILED_LOOP = True  # tests switch it off to compare the compiled loop with the Python one


def _compiled_loop(
    tgt_n, src_n, zt_pad, kept, w, lam, floor, sigma2, single, tol, max_iter, accelerate,
    order, target_order,
):  # fmt: skip
    """register_nonrigid's low-rank EM loop in one call of the compiled kernel.

    Returns ``((U, moved, sigma2), c, iterations, converged, objective)`` in normalized
    units, ``U`` the field's coordinates ``Z' W`` (``kept`` x D); None where an M-step's
    Cholesky fails (the caller's loop then solves it with checks).
    """
    m, d = src_n.shape
    u = np.empty((zt_pad.shape[0], d))
    moved = np.empty((m, d))
    ok, it, converged, sigma2, objective, c = _estep._cestep.em_lowrank(
        tgt_n, src_n, zt_pad, tgt_n.shape[0], m, zt_pad.shape[0], d, w, lam, floor,
        _TRUNCATE_EPS, sigma2, single, tol, max_iter, accelerate, order, target_order, u, moved,
    )  # fmt: skip
    if not ok:
        return None
    # the zero rows of the padded factor give zero rows of U: drop them
    return (u[:kept], moved, sigma2), c, it, bool(converged), objective


# --------------------------------------------------------------------------- public API
def register_nonrigid(
    source,
    target,
    *,
    kernel_width: float = 2.0,
    smoothness: float = 2.0,
    outlier_weight: float = 0.1,
    tol: float = 1e-5,
    max_iter: int = 150,
    normalize: bool = True,
    low_rank: int | str | None = "auto",
    dtype=np.float64,
    warm_start: CPDResult | None = None,
    compiled: bool = True,
    accelerate: bool = True,
) -> CPDResult:
    """Nonrigid Coherent Point Drift: ``T(Y) = Y + G W`` with a Gaussian kernel G.

    Parameters
    ----------
    source : (M, D) float
        The moving set Y (GMM centroids), e.g. metres.
    target : (N, D) float
        The fixed set X (data).
    kernel_width : float
        beta in [1]: width of the Gaussian kernel G, in normalized units when
        ``normalize`` (fractions of the target's RMS radius), else input units.
    smoothness : float
        lambda in [1]: weight of the motion-coherence regularizer.
    outlier_weight : float
        w in [1], in [0, 1): weight of the uniform outlier component.
    tol : float
        Stop when the relative change of the objective (negative log-likelihood plus
        ``lambda / 2 tr(W' G W)``) between iterations is at most ``tol``.
    max_iter : int
        At most this many EM iterations; reaching it sets ``converged=False`` and warns.
    normalize : bool
        Register in coordinates where the target has zero mean and unit RMS radius (one
        similarity applied to both sets), so ``kernel_width``, ``smoothness`` and ``tol``
        do not depend on units. Results are returned in input units. A target whose
        points all coincide (RMS radius at most 1e-9 of its largest absolute
        coordinate: copies of one point, up to rounding) has no radius: the unit is then
        the RMS distance of the source points to it (their common point's largest
        absolute coordinate when the source is that same point), so the result still
        does not depend on units; see Notes.
    low_rank : "auto", None or int
        "auto" (the default): exact up to 64 points; above, a 64-landmark Nyström
        factor ``G ~ Z Z'`` when at most 80% of the landmark kernel's eigenvalues
        exceed 1e-10 of the largest (the landmarks span G: with ``kernel_width=2`` on
        a body K' is about 50), else the exact solve up to 3,000 points and the
        factor above. Narrow kernels (``kernel_width=0.5`` at 400 points) stay exact.
        At convergence "auto" checks the factor: when ``smoothness * sigma2`` is below
        1% of its trace error ``sum_m (1 - |z_m|^2)`` (a fit finer than the factor
        can follow: near noise-free data) it goes on with the exact kernel to the
        exact fixed point (up to 3,000 points). So the defaults recover noise-free
        warps to the micrometre like the exact solve, and noisy data (sensor noise of
        a millimetre or more) never pay for the exact solve: the factor moves the
        result 0.012-0.036 mm RMS from the exact solve's with 2-3 mm noise. None:
        exact dense kernel and a Cholesky M-step (O(M^3) per iteration, M x M
        memory: fine up to a few thousand points). An int K: a rank-K factor (K
        landmarks drawn with a fixed seed; landmark eigenvalues below 1e-10 of the
        largest dropped, K' <= K kept) and a K' x K' Woodbury M-step, O(M K'^2) per
        iteration and O(M K) memory, without the exact polish.
    dtype : numpy.float32 or numpy.float64
        Precision of the E-step (the dominant cost): float32 computes the kernel
        values and exponentials in float32 (16 per AVX-512 vector: 1.15-1.6x faster
        registrations), statistics accumulate and the M-step runs in float64.
    warm_start : CPDResult or None
        A previous result (e.g. the previous frame's). Its final ``sigma2`` (input
        units, re-normalized) replaces the closed-form initial sigma^2. The source set
        may differ from the previous one, so W is not transferred.
    compiled : bool
        Use the compiled E-step and low-rank M-step when built (``False`` forces
        their NumPy twins). With a fixed factor (an int ``low_rank``, or "auto" above
        3,000 points, where it never polishes) the whole EM loop runs in one compiled
        call: the same steps as the Python loop, whose sums round differently (the
        tracker's registrations came out within 1e-11 m of it).
    accelerate : bool
        Default True: SQUAREM extrapolation of EM (Varadhan & Roland 2008, scheme S3)
        on (W, T, log sigma^2): every second M-step, the last two EM steps give a
        steplength and an extrapolated point, kept only when its objective is no
        worse than the EM iterate's (else plain EM goes on). The fixed points are
        EM's; the result differs from plain EM by what ``tol`` allows (0.04-0.06 mm
        RMS at 400-2,000 points with ``tol=1e-5``) in about half the iterations.
        ``False``: plain EM, step for step as in [1] (and pycpd).

    The exact, step-for-step CPD of [1] is ``low_rank=None, accelerate=False``: it
    agrees with pycpd to 1e-8 and with itself across unit scalings and E-step
    builds to 1e-9. The defaults are the fast configuration (8x fewer CPU seconds
    at 400 points, 38x at 2,000; docs/BENCHMARKS.md) and agree with it to ``tol``
    (0.04 mm RMS apart on the 400-point benchmark problem).

    Returns
    -------
    CPDResult
        ``kind="nonrigid"``. ``iterations`` counts M-steps.

    Raises
    ------
    ValueError
        Bad shapes, non-finite values, empty sets or out-of-range parameters.

    Warns
    -----
    ConvergenceWarning
        When ``max_iter`` is reached first.

    Notes
    -----
    Frame-to-frame tracking: call ``register_nonrigid(prev_points, points,
    warm_start=prev_result, tol=1e-4)`` each frame. Only sigma^2 is
    transferred (the source set changes every frame, so W and the posterior cannot
    be; starting from the previous displacement field as a constant-velocity guess was
    measured and cost iterations). On 400-point humanoid frames 3 degrees apart
    (``kernel_width=2``) warm start and ``tol=1e-4`` took 6 M-steps and 1.5-2.2 ms
    CPU with the defaults, against 11-32 M-steps and 17-47 ms for the exact plain
    EM, at equal RMS to the truth (``tol=1e-4`` stops before CPD slides points along
    the resampled surface; docs/BENCHMARKS.md). Labels pass through
    :meth:`CPDResult.transfer_labels`.
    CPD's regularizer weakens as M grows (the eigenvalues of G grow with M):
    ``smoothness`` tuned at 400 points corresponds to about ``smoothness * M / 400``
    at M points.

    Degenerate sets (all points one point, up to 1e-9 of the coordinates' magnitude)
    are registered, not rejected, with the same result in any unit: a single source
    point (or copies of one) moves onto a single target point to rounding (a
    translation); many source points onto a single target point are fitted as usual
    (the nearest ones land on it, the regularizer keeps the rest coherent); a single
    source point moves towards the target's posterior-weighted centroid.

    Examples
    --------
    >>> import numpy as np
    >>> rng = np.random.default_rng(0)
    >>> y = rng.normal(size=(50, 3))
    >>> res = register_nonrigid(y, y + 0.01 * np.sin(y), outlier_weight=0.0)
    >>> bool(np.abs(res.moved - (y + 0.01 * np.sin(y))).max() < 2e-3)
    True
    """
    name = "register_nonrigid"
    src, tgt, w, tol, max_iter, dt = _check_common(
        name, source, target, outlier_weight, tol, max_iter, dtype, warm_start
    )
    beta = check_scalar(kernel_width, "kernel_width", low=0.0, caller=name)
    lam = check_scalar(smoothness, "smoothness", low=0.0, caller=name)
    if low_rank is not None and not (isinstance(low_rank, str) and low_rank == "auto"):
        if isinstance(low_rank, str):
            raise ValueError(
                f"The 'low_rank' parameter of {name} must be None, 'auto' or an int >= 1. "
                f"Got {low_rank!r} instead."
            )
        low_rank = check_scalar(
            low_rank, "low_rank", low=1, include_low=True, integer=True, caller=name
        )
    accelerate = bool(accelerate)
    m, d = src.shape
    n = tgt.shape[0]
    centre, unit, _, _ = _normalization(tgt, src, normalize)
    tgt_n = (tgt - centre) / unit
    src_n = (src - centre) / unit
    single = dt == np.float32
    g, lowrank = _choose_kernel(src_n, beta, low_rank)
    z = None if lowrank is None else np.ascontiguousarray(lowrank[0])
    floor = _SIGMA2_FLOOR_32 if single else _SIGMA2_FLOOR
    half_lam = 0.5 * lam
    zt_pad = None  # the compiled low-rank M-step's Z' (K', M), padded to K' = 0 mod 4
    if z is not None and compiled and _estep.has_compiled_kernel():
        zt_pad = np.zeros((-(-z.shape[1] // 4) * 4, m))
        zt_pad[: z.shape[1]] = z.T
    order = np.arange(m, dtype=np.int64)  # the compiled E-step's sorts, kept between calls
    target_order = np.arange(n, dtype=np.int64)

    def e_step(state):
        """Posterior statistics and the objective at ``state = (W, moved, sigma2)``."""
        wm, mv, s2 = state
        c = outlier_constant(s2, w, m, n, d)
        stats = _estep.estep_stats(
            tgt_n,
            mv,
            s2,
            c,
            compiled=compiled,
            truncate_eps=_TRUNCATE_EPS,
            single=single,
            order=order,
            target_order=target_order,
        )
        # tr(W' G W): W . (T - Y) exactly; with G ~ Z Z' and wm = Z' W it is |wm|^2
        reg = float(np.sum(wm * (mv - src_n))) if z is None else float(np.vdot(wm, wm))
        obj = -stats[3] + 0.5 * n * d * math.log(s2) + half_lam * reg
        return (*stats, c), obj

    work = None if g is None else np.empty_like(g)

    def m_step(stats, s2):
        p1, _, px, _, np_, xpx, _ = stats
        if z is None:
            wm = _solve_nonrigid(g, None, p1, px, src_n, s2, lam, work)
            mv = src_n + g @ wm
            pxm = float(np.vdot(px, mv))
            tpt = float(p1 @ np.einsum("ij,ij->i", mv, mv))
        else:  # the coordinates Z' W of the displacement (K' x D), see _solve_low_rank
            wm = mv = None
            if zt_pad is not None:
                u4, mv = np.empty((zt_pad.shape[0], d)), np.empty((m, d))
                ok, pxm, tpt = _estep._cestep.lowrank_mstep(
                    zt_pad, m, zt_pad.shape[0], d, p1, px, src_n, s2 * lam, u4, mv
                )
                # the zero rows of the padded factor give zero rows of U: drop them
                wm = u4[: z.shape[1]] if ok else None
            if wm is None:
                wm = _solve_low_rank(z, p1, px, src_n, s2 * lam)
                mv = src_n + z @ wm
                pxm = float(np.vdot(px, mv))
                tpt = float(p1 @ np.einsum("ij,ij->i", mv, mv))
        s2 = abs(xpx - 2.0 * pxm + tpt) / (np_ * d)
        return wm, mv, max(s2, floor)

    # low_rank="auto" checks the factor at convergence: when the fit is finer than the
    # factor (lambda sigma^2 below _AUTO_POLISH of its trace error sum_m (1 - |z_m|^2),
    # i.e. near noise-free data) it polishes with the exact kernel (M <= 3000)
    polish_trace = None
    if low_rank == "auto" and z is not None and m <= _AUTO_EXACT_MAX:
        polish_trace = float(m - np.vdot(z, z))

    def switch_to_exact():
        """True (and the exact kernel in place) when the low-rank fit should be polished."""
        nonlocal g, z, zt_pad, work, lowrank, polish_trace
        if polish_trace is None or lam * state[2] >= _AUTO_POLISH * polish_trace:
            return False
        polish_trace = lowrank = z = zt_pad = None
        g = gaussian_kernel(src_n, src_n, beta)
        work = np.empty_like(g)
        return True

    s2_start = _start_sigma2(tgt_n, src_n, warm_start, unit, floor)
    fused = None
    if zt_pad is not None and polish_trace is None and _COMPILED_LOOP:
        # The whole loop below in one compiled call (the same steps; its sums round
        # differently, so the result agrees with this loop's to rounding, not bit for bit).
        fused = _compiled_loop(
            tgt_n, src_n, zt_pad, z.shape[1], w, lam, floor, s2_start, single, tol, max_iter,
            accelerate, order, target_order,
        )  # fmt: skip
    if fused is not None:
        state, c, it, converged, objective = fused
    else:
        coef0 = np.zeros((m if z is None else z.shape[1], d))
        state = (coef0, src_n.copy(), s2_start)
        stats, objective = e_step(state)
        converged = False
        it = 0  # M-steps done
        step_max = 4.0
        no_accel = False  # one plain EM step after the switch to the exact kernel
        while True:
            if it >= max_iter:
                break
            if stats[4] <= 0.0:  # every target point is an outlier: nothing to fit
                converged = True
                break
            prev_state = state
            new = m_step(stats, state[2])
            it += 1
            new_stats, new_obj = e_step(new)
            done = _relative_change(new_obj, objective) <= tol
            state, stats, obj_1, objective = new, new_stats, objective, new_obj
            if done and switch_to_exact():
                objective, no_accel = np.inf, True  # W is re-solved, tr(W'GW) with it
                continue
            if done:
                converged = True
                break
            if not accelerate or no_accel or it + 2 > max_iter or stats[4] <= 0.0:
                no_accel = False
                continue
            # SQUAREM (Varadhan & Roland 2008, scheme S3) on (W, moved, log sigma2): one more
            # EM step, a steplength from the two differences, one step from the extrapolation;
            # the extrapolated point is kept only if its objective is no worse.
            theta0, theta1 = prev_state, state
            theta2 = m_step(stats, state[2])
            it += 1
            r = theta1[1] - theta0[1]
            v = theta2[1] - theta1[1] - r
            rr, vv = float(np.sum(r * r)), float(np.sum(v * v))
            alpha = -np.sqrt(rr / vv) if vv > 0.0 else -1.0
            alpha = max(min(alpha, -1.0), -step_max)
            fallback = True
            if alpha < -1.0:
                ls = [np.log(t[2]) for t in (theta0, theta1, theta2)]
                ls2 = ls[0] - 2 * alpha * (ls[1] - ls[0]) + alpha**2 * (ls[2] - 2 * ls[1] + ls[0])
                ls2 = min(ls2, max(ls) + 5.0)  # no overflow; such a step is rejected anyway
                ext = tuple(
                    theta0[k]
                    - 2 * alpha * (theta1[k] - theta0[k])
                    + alpha**2 * (theta2[k] - 2 * theta1[k] + theta0[k])
                    for k in (0, 1)
                ) + (max(float(np.exp(ls2)), floor),)
                ext_stats, ext_obj = e_step(ext)
                if np.isfinite(ext_obj) and ext_obj <= objective:
                    fallback = False
                    if alpha <= -step_max:
                        step_max *= 4.0
                    state, stats, obj_1, objective = ext, ext_stats, objective, ext_obj
            if fallback:
                stats, new_obj = e_step(theta2)
                state, obj_1, objective = theta2, objective, new_obj
            if _relative_change(objective, obj_1) <= tol:
                if switch_to_exact():
                    objective, no_accel = np.inf, True
                    continue
                converged = True
                break
        c = stats[6]
    wmat, moved, sigma2 = state
    _finish(converged, name, max_iter, tol)
    landmarks = landmark_coef = None
    if lowrank is not None:  # wmat holds Z' W: the field is G(p, landmarks) proj Z' W
        landmarks = lowrank[1]
        landmark_coef = lowrank[2] @ wmat
        wmat = None
    return CPDResult(
        kind="nonrigid",
        moved=moved * unit + centre,
        sigma2=sigma2 * unit**2,
        iterations=it,
        converged=converged,
        objective=float(objective),
        _target_n=tgt_n,
        _source_n=src_n,
        _moved_n=moved,
        _coef=wmat,
        _sigma2_n=sigma2,
        _outlier_c=c,
        _centre=centre,
        _unit=unit,
        _kernel_width=beta,
        _landmarks=landmarks,
        _landmark_coef=landmark_coef,
    )


def _linear_cpd(
    name,
    kind,
    source,
    target,
    *,
    outlier_weight,
    tol,
    max_iter,
    normalize,
    dtype,
    warm_start,
    compiled,
    with_scale=True,
):
    src, tgt, w, tol, max_iter, dt = _check_common(
        name, source, target, outlier_weight, tol, max_iter, dtype, warm_start
    )
    m, d = src.shape
    n = tgt.shape[0]
    centre, unit, target_point, source_point = _normalization(tgt, src, normalize)
    tgt_n = (tgt - centre) / unit
    src_n = (src - centre) / unit
    # the source's coordinates are known to rounding: directions in which its
    # (normalized) spread is below this are no spread at all (see _affine_matrix)
    src_resolution = _DEGENERATE_RTOL * _magnitude(src) / unit
    tgt_e = tgt_n.astype(dt)
    mat = np.eye(d)
    t = np.zeros(d)
    rot, s = np.eye(d), 1.0
    if warm_start is not None and warm_start.matrix is not None:
        # physical  y -> A y + b  becomes  y_n -> A y_n + (A c + b - c) / unit
        mat = warm_start.matrix.copy()
        t = (mat @ centre + warm_start.translation - centre) / unit
        if kind == "rigid":
            s = float(warm_start.scale)
            rot = warm_start.rotation.copy()
            if rot.shape != (d, d):
                rot, s, mat = np.eye(d), 1.0, np.eye(d)
    moved = src_n @ mat.T + t
    floor = _SIGMA2_FLOOR_32 if dt == np.float32 else _SIGMA2_FLOOR
    sigma2 = _start_sigma2(tgt_n, moved, warm_start, unit, floor)
    xx = np.einsum("ij,ij->i", tgt_n, tgt_n)
    obj_old = np.inf
    converged = False
    objective = np.inf
    c = 0.0
    it = 0
    for it in range(max_iter + 1):
        c = outlier_constant(sigma2, w, m, n, d)
        p1, pt1, px, log_den = _estep.estep(
            tgt_e, moved.astype(dt), sigma2, c, compiled=compiled, truncate_eps=_TRUNCATE_EPS
        )
        objective = -log_den + 0.5 * n * d * np.log(sigma2)
        if it > 0 and _relative_change(objective, obj_old) <= tol:
            converged = True
            break
        if it == max_iter:
            break
        obj_old = objective
        np_ = float(p1.sum())
        if np_ <= 0.0:
            converged = True
            break
        mu_x = pt1 @ tgt_n / np_
        mu_y = p1 @ src_n / np_
        a = px.T @ src_n - np_ * np.outer(mu_x, mu_y)  # X^' P' Y^ (D x D)
        if target_point:  # X^ is rounding noise: no direction to align with
            a = np.zeros_like(a)
        xpx = float(pt1 @ xx) - np_ * float(mu_x @ mu_x)
        if kind == "rigid":
            ypy = float(p1 @ np.einsum("ij,ij->i", src_n, src_n)) - np_ * float(mu_y @ mu_y)
            if source_point:  # rotation and scale of a single point: none (identity)
                rot, s = np.eye(d), 1.0
                mat = rot
                t = mu_x - mu_y
                sigma2 = (xpx - 2.0 * float(np.trace(a)) + ypy) / (np_ * d)
            else:
                if target_point:  # A = 0: any rotation fits; the identity, explicitly
                    rot = np.eye(d)
                else:
                    u, _, vt = np.linalg.svd(a)
                    cdiag = np.ones(d)
                    cdiag[-1] = np.linalg.det(u @ vt)
                    rot = (u * cdiag) @ vt
                tr_ar = float(np.sum(a * rot))
                s = tr_ar / ypy if (with_scale and ypy > 0) else 1.0
                mat = s * rot
                t = mu_x - mat @ mu_y
                sigma2 = (xpx - s * tr_ar) / (np_ * d)
        else:
            yhat = src_n - mu_y
            ypy = (yhat.T * p1) @ yhat
            mat, solved = _affine_matrix(a, ypy, np_ * src_resolution**2, source_point)
            t = mu_x - mat @ mu_y
            if solved:  # B Y^' dP1 Y^ = A
                sigma2 = (xpx - float(np.sum(a * mat))) / (np_ * d)
            else:
                sigma2 = xpx - 2.0 * float(np.sum(a * mat)) + float(np.sum((mat @ ypy) * mat))
                sigma2 /= np_ * d
        sigma2 = max(abs(sigma2), floor)
        moved = src_n @ mat.T + t
    _finish(converged, name, max_iter, tol)
    # back to input units: y -> A y + (unit t + c - A c)
    trans = unit * t + centre - mat @ centre
    return CPDResult(
        kind=kind,
        moved=moved * unit + centre,
        sigma2=sigma2 * unit**2,
        iterations=it,
        converged=converged,
        objective=float(objective),
        rotation=rot if kind == "rigid" else None,
        scale=float(s) if kind == "rigid" else None,
        matrix=mat,
        translation=trans,
        _target_n=tgt_n,
        _source_n=src_n,
        _moved_n=moved,
        _sigma2_n=sigma2,
        _outlier_c=c,
        _centre=centre,
        _unit=unit,
    )


def _affine_matrix(a, ypy, floor, source_point):
    """The affine M-step's ``B = A (Y^' dP1 Y^)^-1``; ``(B, True)`` when solved as is.

    ``ypy`` (D x D, symmetric positive semi-definite) is singular when the source
    has no spread in some direction (a single point, a line, a plane): B is then
    undetermined there. Eigen-directions of ``ypy`` with eigenvalue at most ``floor``
    (the source's rounding) or ``D eps`` times the largest are dropped and B is the
    solution closest to the identity, ``I + (A - ypy) V diag(1/e) V'`` over the kept
    directions: it maps the directions without spread as the identity does (a single
    source point: ``B = I``, a pure translation). Returns ``(B, False)`` then.
    """
    d = ypy.shape[0]
    if source_point:
        return np.eye(d), False
    ev, vec = np.linalg.eigh(ypy)
    keep = ev > max(floor, ev[-1] * d * np.finfo(np.float64).eps)
    if keep.all():
        try:
            return np.linalg.solve(ypy.T, a.T).T, True
        except np.linalg.LinAlgError:  # pragma: no cover - ruled out by the eigenvalues
            pass
    vk = vec[:, keep]
    return np.eye(d) + ((a - ypy) @ vk / ev[keep]) @ vk.T, False


def register_rigid(
    source,
    target,
    *,
    scale: bool = True,
    outlier_weight: float = 0.1,
    tol: float = 1e-5,
    max_iter: int = 150,
    normalize: bool = True,
    dtype=np.float64,
    warm_start: CPDResult | None = None,
    compiled: bool = True,
) -> CPDResult:
    """Rigid (similarity) Coherent Point Drift: ``T(y) = s R y + t``.

    Parameters
    ----------
    source : (M, D) float
        The moving set Y.
    target : (N, D) float
        The fixed set X.
    scale : bool
        Estimate the isotropic scale s (else s = 1).
    outlier_weight, tol, max_iter, normalize, dtype, compiled
        As in :func:`register_nonrigid`.
    warm_start : CPDResult or None
        A previous result: its transform (when it has one) and its ``sigma2`` start
        this registration.

    Returns
    -------
    CPDResult
        ``kind="rigid"``, with ``rotation``, ``scale``, ``matrix`` (s R) and
        ``translation`` in input units.

    Notes
    -----
    A single source point (all points coincide up to 1e-9 of their coordinates'
    magnitude) has no rotation or scale: it gets ``rotation = I`` and ``scale = 1``, a
    pure translation onto the target's (weighted) centroid. A single target point gives
    no direction to align with: ``rotation = I``, and the fitted scale is 0 (the source
    shrinks onto it; with ``scale=False`` it is only translated). Either way the
    result does not depend on units (see ``normalize`` in :func:`register_nonrigid`).

    Examples
    --------
    >>> import numpy as np
    >>> y = np.random.default_rng(1).normal(size=(60, 3))
    >>> res = register_rigid(y, y + [0.5, 0.0, 0.0])
    >>> bool(np.allclose(res.translation, [0.5, 0.0, 0.0], atol=1e-4))
    True
    """
    scale = bool(scale)
    return _linear_cpd(
        "register_rigid",
        "rigid",
        source,
        target,
        outlier_weight=outlier_weight,
        tol=tol,
        max_iter=max_iter,
        normalize=normalize,
        dtype=dtype,
        warm_start=warm_start,
        compiled=compiled,
        with_scale=scale,
    )


def register_affine(
    source,
    target,
    *,
    outlier_weight: float = 0.1,
    tol: float = 1e-5,
    max_iter: int = 150,
    normalize: bool = True,
    dtype=np.float64,
    warm_start: CPDResult | None = None,
    compiled: bool = True,
) -> CPDResult:
    """Affine Coherent Point Drift: ``T(y) = B y + t``.

    Parameters are as in :func:`register_rigid` (without ``scale``).

    Where the source has no spread in some direction (a single point, a line, a
    plane: the M-step's ``Y' dP1 Y`` is singular, to rounding) B is not determined
    there: B is then the solution closest to the identity, mapping those directions
    as the identity does (a single source point: ``B = I``, a translation; a planar
    source: B fitted in the plane, the normal kept). A single target point gives
    ``B = 0``.

    Returns
    -------
    CPDResult
        ``kind="affine"`` with ``matrix`` (B) and ``translation`` in input units.

    Examples
    --------
    >>> import numpy as np
    >>> y = np.random.default_rng(2).normal(size=(60, 3))
    >>> b = np.diag([1.2, 0.9, 1.0])
    >>> res = register_affine(y, y @ b.T)
    >>> bool(np.allclose(res.matrix, b, atol=1e-3))
    True
    """
    return _linear_cpd(
        "register_affine",
        "affine",
        source,
        target,
        outlier_weight=outlier_weight,
        tol=tol,
        max_iter=max_iter,
        normalize=normalize,
        dtype=dtype,
        warm_start=warm_start,
        compiled=compiled,
    )
