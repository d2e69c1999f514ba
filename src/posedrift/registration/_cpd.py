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

import warnings

import numpy as np
import scipy.linalg as sla

from posedrift._validation import check_points, check_scalar
from posedrift.registration import _estep
from posedrift.registration._result import ConvergenceWarning, CPDResult

_SIGMA2_FLOOR = 1e-10  # in normalized units (squared fractions of the target's RMS radius)
_SIGMA2_FLOOR_32 = 1e-7  # float32 E-step: distances are only good to ~1e-7 relative
_TRUNCATE_EPS = 1e-12  # compiled E-step: drop kernel terms below this share of the outlier term


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


def gaussian_kernel(a: np.ndarray, b: np.ndarray, beta: float) -> np.ndarray:
    """``exp(-|a_i - b_j|^2 / (2 beta^2))`` without an (I, J, D) temporary."""
    d2 = np.einsum("ij,ij->i", a, a)[:, None] + np.einsum("ij,ij->i", b, b)[None, :]
    d2 -= 2.0 * (a @ b.T)
    np.maximum(d2, 0.0, out=d2)
    d2 *= -1.0 / (2.0 * beta * beta)
    return np.exp(d2, out=d2)


def low_rank_kernel(source: np.ndarray, beta: float, rank: int) -> np.ndarray:
    """A factor Z (M, K') with ``G ~ Z Z'`` (Nyström, K = ``rank`` landmarks).

    Landmarks: ``rank`` source points drawn with a fixed seed (deterministic). With
    ``W_k = U diag(e) U'`` the landmark kernel, ``Z = C U diag(e)^(-1/2)`` over the
    eigenvalues above ``1e-10`` of the largest (K' <= K), so ``Z Z'`` keeps the leading
    eigen-structure of G. O(M K) kernel values and O(M K^2 + K^3) flops; never the
    M x M kernel.
    """
    m = source.shape[0]
    rank = min(rank, m)
    land = np.sort(np.random.default_rng(0).choice(m, size=rank, replace=False))
    c = gaussian_kernel(source, source[land], beta)  # (M, K)
    ev, u = np.linalg.eigh(c[land])
    keep = ev > ev[-1] * 1e-10
    return c @ (u[:, keep] / np.sqrt(ev[keep]))


def _solve_nonrigid(g, lowrank, p1, px, source, sigma2, smoothness):
    """Symmetric M-step: returns W with ``(G + lambda s2 dP1^-1) W = dP1^-1 P X - Y``."""
    reg = smoothness * sigma2
    if lowrank is None:
        sq = np.sqrt(p1)
        # rhs = dP1^(-1/2) (P X - dP1 Y), zero where P1 == 0 (there P X == 0 too)
        safe = np.where(sq > 0, sq, 1.0)
        rhs = px / safe[:, None] - sq[:, None] * source
        a = g * sq[:, None]
        a *= sq[None, :]
        a.flat[:: a.shape[0] + 1] += reg
        v = sla.cho_solve(
            sla.cho_factor(a, lower=True, check_finite=False), rhs, check_finite=False
        )
        return sq[:, None] * v
    z = lowrank
    b = px - p1[:, None] * source
    # Woodbury: (dP1 Z Z' + s I)^-1 = (I - dP1 Z (s I + Z' dP1 Z)^-1 Z') / s
    small = (z.T * p1) @ z  # K x K
    small.flat[:: small.shape[0] + 1] += reg
    inner = sla.cho_solve(sla.cho_factor(small, check_finite=False), z.T @ b, check_finite=False)
    return (b - p1[:, None] * (z @ inner)) / reg


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


def _normalization(target: np.ndarray, normalize: bool) -> tuple[np.ndarray, float]:
    """One similarity for both sets: the target's centroid and RMS radius."""
    d = target.shape[1]
    if not normalize:
        return np.zeros(d), 1.0
    centre = target.mean(axis=0)
    unit = float(np.sqrt(np.mean(np.sum((target - centre) ** 2, axis=1))))
    if not np.isfinite(unit) or unit <= 0.0:
        unit = 1.0
    return centre, unit


def _start_sigma2(tgt_n, moved_n, warm_start, unit, floor):
    s2 = initial_sigma2(tgt_n, moved_n)
    if warm_start is not None:
        s2 = warm_start.sigma2 / unit**2
    return max(s2, floor)


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
    low_rank: int | None = None,
    dtype=np.float64,
    warm_start: CPDResult | None = None,
    compiled: bool = True,
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
        do not depend on units. Results are returned in input units.
    low_rank : int or None
        None: exact dense kernel and a Cholesky M-step (O(M^3) per iteration, M x M
        memory: fine up to a few thousand points). An int K: a rank-K Nyström
        factor ``G ~ Z Z'`` (K landmark points drawn with a fixed seed) and a K x K
        Woodbury M-step: O(M K^2) per iteration, O(M K) memory. K = 60-100 matches
        the exact result to a fraction of a millimetre on 400-10,000-point bodies
        with ``kernel_width=2`` (see docs/BENCHMARKS.md).
    dtype : numpy.float32 or numpy.float64
        Precision of the E-step (the dominant cost); statistics accumulate and the
        M-step runs in float64.
    warm_start : CPDResult or None
        A previous result (e.g. the previous frame's). Its final ``sigma2`` (input
        units, re-normalized) replaces the closed-form initial sigma^2. The source set
        may differ from the previous one, so W is not transferred.
    compiled : bool
        Use the compiled E-step when built (``False`` forces the NumPy twin).

    Returns
    -------
    CPDResult
        ``kind="nonrigid"``.

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
    warm_start=prev_result)`` each frame. Only sigma^2 is transferred (the source set
    changes every frame, so W and the posterior cannot be); on consecutive humanoid
    frames this cut the iterations by a third to a half (docs/BENCHMARKS.md). Labels
    pass through :meth:`CPDResult.transfer_labels`. CPD's regularizer weakens as M
    grows (the eigenvalues of G grow with M): ``smoothness`` tuned at 400 points
    corresponds to about ``smoothness * M / 400`` at M points.

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
    if low_rank is not None:
        low_rank = check_scalar(
            low_rank, "low_rank", low=1, include_low=True, integer=True, caller=name
        )
    m, d = src.shape
    n = tgt.shape[0]
    centre, unit = _normalization(tgt, normalize)
    tgt_n = (tgt - centre) / unit
    src_n = (src - centre) / unit
    tgt_e = tgt_n.astype(dt)
    if low_rank is None or low_rank >= m:
        g, lowrank = gaussian_kernel(src_n, src_n, beta), None
    else:
        g, lowrank = None, low_rank_kernel(src_n, beta, low_rank)
    floor = _SIGMA2_FLOOR_32 if dt == np.float32 else _SIGMA2_FLOOR
    sigma2 = _start_sigma2(tgt_n, src_n, warm_start, unit, floor)
    wmat = np.zeros((m, d))
    moved = src_n.copy()
    obj_old = np.inf
    converged = False
    it = 0
    c = outlier_constant(sigma2, w, m, n, d)
    objective = np.inf
    for it in range(max_iter + 1):
        c = outlier_constant(sigma2, w, m, n, d)
        p1, pt1, px, log_den = _estep.estep(
            tgt_e, moved.astype(dt), sigma2, c, compiled=compiled, truncate_eps=_TRUNCATE_EPS
        )
        gw = moved - src_n
        objective = -log_den + 0.5 * n * d * np.log(sigma2) + 0.5 * lam * float(np.sum(wmat * gw))
        if it > 0 and _relative_change(objective, obj_old) <= tol:
            converged = True
            break
        if it == max_iter:
            break
        obj_old = objective
        np_ = float(p1.sum())
        if np_ <= 0.0:  # every target point is an outlier: nothing to fit
            converged = True
            break
        wmat = _solve_nonrigid(g, lowrank, p1, px, src_n, sigma2, lam)
        moved = src_n + _kernel_apply(g, lowrank, wmat)
        xpx = float(pt1 @ np.einsum("ij,ij->i", tgt_n, tgt_n))
        tpt = float(p1 @ np.einsum("ij,ij->i", moved, moved))
        sigma2 = abs(xpx - 2.0 * float(np.sum(px * moved)) + tpt) / (np_ * d)
        sigma2 = max(sigma2, floor)
    _finish(converged, name, max_iter, tol)
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
    centre, unit = _normalization(tgt, normalize)
    tgt_n = (tgt - centre) / unit
    src_n = (src - centre) / unit
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
        xpx = float(pt1 @ xx) - np_ * float(mu_x @ mu_x)
        if kind == "rigid":
            u, _, vt = np.linalg.svd(a)
            cdiag = np.ones(d)
            cdiag[-1] = np.linalg.det(u @ vt)
            rot = (u * cdiag) @ vt
            ypy = float(p1 @ np.einsum("ij,ij->i", src_n, src_n)) - np_ * float(mu_y @ mu_y)
            tr_ar = float(np.sum(a * rot))
            s = tr_ar / ypy if (with_scale and ypy > 0) else 1.0
            mat = s * rot
            t = mu_x - mat @ mu_y
            sigma2 = (xpx - s * tr_ar) / (np_ * d)
        else:
            yhat = src_n - mu_y
            ypy = (yhat.T * p1) @ yhat
            try:
                mat = np.linalg.solve(ypy.T, a.T).T  # B = A (Y^' dP1 Y^)^-1
            except np.linalg.LinAlgError:
                mat = a @ np.linalg.pinv(ypy)
            t = mu_x - mat @ mu_y
            sigma2 = (xpx - float(np.sum(a * mat))) / (np_ * d)
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
