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
    """E-step through the compiled kernel (float64 only) when built, else :func:`estep_numpy`.

    With ``truncate_eps > 0`` (compiled kernel only) the source is sorted along its
    longest axis and each target point sums only the source points within
    :func:`truncation_halfwidth` along it: every posterior entry is then exact to
    ``truncate_eps`` absolute.
    """
    if (
        compiled
        and _cestep is not None
        and target.dtype == np.float64
        and moved.dtype == np.float64
    ):
        n, d = target.shape
        m = moved.shape[0]
        p1 = np.zeros(m)
        pt1 = np.empty(n)
        px_t = np.zeros((d, m))
        tgt = np.ascontiguousarray(target)
        half = truncation_halfwidth(sigma2, c, truncate_eps)
        if half > 0.0:
            extent = moved.max(axis=0) - moved.min(axis=0)
            axis = int(np.argmax(extent))
            if half >= extent[axis]:
                half = 0.0
        if half > 0.0:
            order = np.argsort(moved[:, axis], kind="stable")
            moved_t = np.ascontiguousarray(moved[order].T)
            log_den = _cestep.estep(
                tgt, moved_t, n, m, d, float(sigma2), float(c), p1, pt1, px_t, axis, half
            )
            p1_out = np.empty(m)
            p1_out[order] = p1
            px = np.empty((m, d))
            px[order] = px_t.T
            return p1_out, pt1, px, float(log_den)
        moved_t = np.ascontiguousarray(moved.T)
        log_den = _cestep.estep(tgt, moved_t, n, m, d, float(sigma2), float(c), p1, pt1, px_t)
        return p1, pt1, px_t.T.copy(), float(log_den)
    return estep_numpy(target, moved, sigma2, c)


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
) -> np.ndarray:
    """``(N, n_labels)``: posterior mass of each label's source points, per target point."""
    n = target.shape[0]
    m = moved.shape[0]
    onehot = np.zeros((m, n_labels))
    onehot[np.arange(m), labels] = 1.0
    out = np.empty((n, n_labels))
    tt = np.einsum("ij,ij->i", moved, moved)
    for sl in _blocks(n, m):
        k = _kernel_block(target[sl], moved, tt, sigma2).astype(np.float64, copy=False)
        den = np.maximum(k.sum(axis=0) + c, _TINY)
        out[sl] = (k.T @ onehot) / den[:, None]
    return out
