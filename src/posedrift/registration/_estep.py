"""CPD E-step kernels: a blocked NumPy kernel and, when built, a fused C twin.

Both return the posterior's sufficient statistics without storing the M x N
posterior: ``P1 = P 1`` (M,), ``Pt1 = P' 1`` (N,), ``PX = P X`` (M, D) and
``sum_n log(den_n)``, where ``P[m, n] = k_mn / den_n``,
``k_mn = exp(-|x_n - t_m|^2 / (2 sigma2))`` and ``den_n = sum_m k_mn + c``.
"""

from __future__ import annotations

import math

import numpy as np

try:  # the compiled twin is optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.registration import _cestep  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _cestep = None

_BLOCK_ELEMENTS = 1 << 21  # ~2M kernel values per block: 16 MB in float64
_TINY = np.finfo(np.float64).tiny


def has_compiled_kernel() -> bool:
    """Whether the compiled E-step extension is importable."""
    return _cestep is not None


def _blocks(n: int, m: int):
    step = max(1, _BLOCK_ELEMENTS // max(m, 1))
    for start in range(0, n, step):
        yield slice(start, min(n, start + step))


def _kernel_block(xb: np.ndarray, moved: np.ndarray, tt: np.ndarray, sigma2: float) -> np.ndarray:
    """``k_mn`` for a block of target points: (M, nb), with exponents clamped.

    float64 expands ``|t|^2 + |x|^2 - 2 t.x`` (one matrix product); float32 sums the
    squared coordinate differences one dimension at a time (accurate relative to the
    distance itself; never an (M, nb, D) temporary).
    """
    if xb.dtype == np.float32:
        d2 = np.zeros((moved.shape[0], xb.shape[0]), dtype=np.float32)
        diff = np.empty_like(d2)
        for k in range(xb.shape[1]):
            np.subtract(moved[:, k, None], xb[None, :, k], out=diff)
            diff *= diff
            d2 += diff
    else:
        xx = np.einsum("ij,ij->i", xb, xb)
        d2 = moved @ xb.T
        d2 *= -2.0
        d2 += tt[:, None]
        d2 += xx[None, :]
        np.maximum(d2, 0.0, out=d2)
    d2 *= d2.dtype.type(-0.5 / sigma2)
    # clamp exponents so that float32 never produces denormals
    lo = -87.0 if d2.dtype == np.float32 else -700.0
    np.maximum(d2, d2.dtype.type(lo), out=d2)
    return np.exp(d2, out=d2)


def estep_numpy(
    target: np.ndarray, moved: np.ndarray, sigma2: float, c: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Blocked NumPy E-step. Works in the dtype of ``target`` and ``moved``.

    Returns
    -------
    p1 : (M,) float64
    pt1 : (N,) float64
    px : (M, D) float64
    log_den : float
        ``sum_n log(den_n)``.
    """
    n, d = target.shape
    m = moved.shape[0]
    p1 = np.zeros(m)
    pt1 = np.empty(n)
    px = np.zeros((m, d))
    log_den = 0.0
    tt = np.einsum("ij,ij->i", moved, moved)
    for sl in _blocks(n, m):
        xb = target[sl]
        k = _kernel_block(xb, moved, tt, sigma2)
        s = k.sum(axis=0, dtype=np.float64)
        den = s + c
        den = np.where(den > _TINY, den, _TINY)
        inv = 1.0 / den
        k *= inv.astype(k.dtype)[None, :]
        p1 += k.sum(axis=1, dtype=np.float64)
        pt1[sl] = s * inv
        px += (k @ xb).astype(np.float64)
        log_den += float(np.log(den).sum())
    return p1, pt1, px, log_den


TRUNCATE_EPS = 1e-12
"""The compiled E-step and label transfer leave out kernel terms below this share of the
outlier term (:func:`truncation_halfwidth`): every posterior entry is exact to it."""


def truncation_halfwidth(sigma2: float, c: float, eps: float) -> float:
    """Distance beyond which every kernel value is below ``eps * c`` (0: no truncation).

    Dropping those terms changes each posterior entry by less than ``eps`` in absolute
    value. Without an outlier term (``c == 0``) nothing is dropped.
    """
    if c <= 0.0 or eps <= 0.0:
        return 0.0
    bound = math.log(eps * c)
    if bound >= 0.0:
        return 0.0
    return math.sqrt(-2.0 * sigma2 * bound)


def estep(
    target: np.ndarray,
    moved: np.ndarray,
    sigma2: float,
    c: float,
    *,
    compiled: bool = True,
    truncate_eps: float = 0.0,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """E-step in the dtype of ``target`` and ``moved``: ``(P1, Pt1, PX, sum log den)``.

    The compiled kernel when built (``compiled=True``), else :func:`estep_numpy`; see
    :func:`estep_stats` for ``truncate_eps``.
    """
    single = target.dtype == np.float32 or moved.dtype == np.float32
    return estep_stats(
        target.astype(np.float64, copy=False),
        moved.astype(np.float64, copy=False),
        sigma2,
        c,
        compiled=compiled,
        truncate_eps=truncate_eps,
        single=single,
    )[:4]


def estep_stats(
    target: np.ndarray,
    moved: np.ndarray,
    sigma2: float,
    c: float,
    *,
    compiled: bool = True,
    truncate_eps: float = 0.0,
    single: bool = False,
    order: np.ndarray | None = None,
    target_order: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, float, float, float]:
    """E-step statistics and the sums the M-step needs, in one pass when compiled.

    Parameters
    ----------
    target : (N, D) float64
    moved : (M, D) float64
    sigma2, c : float
        Kernel variance and the outlier term of the denominator.
    compiled : bool
        Use the compiled kernel when it is built; else (or when absent) the NumPy twin.
    truncate_eps : float
        Compiled kernel only: with ``truncate_eps > 0`` the source is sorted along its
        longest axis and each target point sums only the source points within
        :func:`truncation_halfwidth` along it, so every posterior entry is exact to
        ``truncate_eps`` absolute.
    single : bool
        Kernel values and exponentials in float32 (statistics still in float64).
    order : (M,) int64 or None
        Compiled kernel only: the sort permutation, kept by the caller between the
        E-steps of one registration (an O(M) re-sort); None: a fresh one.
    target_order : (N,) int64 or None
        Compiled kernel only: the same for the target, kept between E-steps; with it
        the truncation window slides along the sorted targets instead of a binary
        search per target point.

    Returns
    -------
    p1 : (M,) float64
    pt1 : (N,) float64
    px : (M, D) float64
    log_den : float
        ``sum_n log(den_n)``.
    n_p : float
        ``sum(p1)``.
    xpx : float
        ``sum_n Pt1_n |x_n|^2``.
    """
    n, d = target.shape
    m = moved.shape[0]
    if compiled and _cestep is not None:
        p1 = np.empty(m)
        pt1 = np.empty(n)
        px = np.empty((m, d))
        if order is None:
            order = np.arange(m, dtype=np.int64)
        args = [
            np.ascontiguousarray(target, dtype=np.float64),
            np.ascontiguousarray(moved, dtype=np.float64),
            n,
            m,
            d,
            float(sigma2),
            float(c),
            float(truncate_eps),
            bool(single),
            p1,
            pt1,
            px,
            order,
        ]
        if target_order is not None:
            args.append(target_order)
        log_den, n_p, xpx = _cestep.estep(*args)
        return p1, pt1, px, log_den, n_p, xpx
    if single:
        target, moved = target.astype(np.float32), moved.astype(np.float32)
    p1, pt1, px, log_den = estep_numpy(target, moved, sigma2, c)
    xx = np.einsum("ij,ij->i", target, target, dtype=np.float64)
    return p1, pt1, px, log_den, float(p1.sum()), float(pt1 @ xx)


def posterior_argmax(
    target: np.ndarray, moved: np.ndarray, sigma2: float, c: float
) -> tuple[np.ndarray, np.ndarray]:
    """For each target point, its most probable source point and that posterior."""
    n = target.shape[0]
    m = moved.shape[0]
    idx = np.empty(n, dtype=np.intp)
    prob = np.empty(n)
    tt = np.einsum("ij,ij->i", moved, moved)
    for sl in _blocks(n, m):
        k = _kernel_block(target[sl], moved, tt, sigma2)
        den = np.maximum(k.sum(axis=0, dtype=np.float64) + c, _TINY)
        best = np.argmax(k, axis=0)
        idx[sl] = best
        prob[sl] = k[best, np.arange(k.shape[1])] / den
    return idx, prob


def posterior_label_mass(
    target: np.ndarray,
    moved: np.ndarray,
    sigma2: float,
    c: float,
    labels: np.ndarray,
    n_labels: int,
    *,
    compiled: bool = True,
    truncate_eps: float = 0.0,
) -> np.ndarray:
    """``(N, n_labels)``: posterior mass of each label's source points, per target point.

    The compiled kernel when built (``compiled=True``: its exponential vectorized for
    the processor at run time, where NumPy's float64 ``exp`` is scalar on processors
    without AVX-512), else the blocked NumPy twin; they agree to about 1e-13 (the
    twin expands squared distances, the kernel sums squared differences). With
    ``truncate_eps > 0`` the kernel sums, for each target point, only the source points
    within :func:`truncation_halfwidth` of it along the source's longest axis, which
    moves every entry by less than ``truncate_eps`` (the twin stays exact).
    """
    n, d = target.shape
    m = moved.shape[0]
    kernel = getattr(_cestep, "label_mass", None) if compiled else None
    if kernel is not None and n and m and sigma2 > 0:  # (the twin covers the edge cases)
        moved = np.ascontiguousarray(moved, dtype=np.float64)
        spans = [moved[:, k].max() - moved[:, k].min() for k in range(d)]  # np.ptp's, cheaper
        axis = int(np.argmax(spans))
        out = np.empty((n, n_labels))
        kernel(
            np.ascontiguousarray(target, dtype=np.float64),
            moved,
            n,
            m,
            d,
            float(sigma2),
            float(c),
            np.ascontiguousarray(labels, dtype=np.int64),
            int(n_labels),
            out,
            axis,
            truncation_halfwidth(float(sigma2), float(c), truncate_eps),
        )
        return out
    onehot = np.zeros((m, n_labels))
    onehot[np.arange(m), labels] = 1.0
    out = np.empty((n, n_labels))
    tt = np.einsum("ij,ij->i", moved, moved)
    for sl in _blocks(n, m):
        k = _kernel_block(target[sl], moved, tt, sigma2).astype(np.float64, copy=False)
        den = np.maximum(k.sum(axis=0) + c, _TINY)
        out[sl] = (k.T @ onehot) / den[:, None]
    return out
