"""Validation at the boundary: one place that checks what enters the library.

Every message names the argument, what was expected and what came, following
scikit-learn's template.
"""

from __future__ import annotations

import math
import numbers
from typing import Any

import numpy as np


def check_points(
    x: Any,
    name: str,
    *,
    dim: int | None = 3,
    min_points: int = 1,
    dtype: type = np.float64,
    caller: str | None = None,
) -> np.ndarray:
    """Return ``x`` as a C-contiguous ``(N, dim)`` finite float array.

    Parameters
    ----------
    x : array_like
        The points.
    name : str
        The argument's name, used in error messages.
    dim : int or None
        Required number of columns; ``None`` accepts any.
    min_points : int
        Smallest accepted number of rows.
    dtype : type
        Output dtype (float32 or float64).
    caller : str, optional
        The public function's name, used in error messages.

    Raises
    ------
    ValueError
        If ``x`` is not 2-D, has the wrong number of columns, too few rows, or
        non-finite values.
    """
    where = f" of {caller}" if caller else ""
    try:
        arr = np.asarray(x, dtype=dtype)
    except (TypeError, ValueError) as exc:
        raise ValueError(
            f"The '{name}' argument{where} must be a numeric array. Got {type(x).__name__}."
        ) from exc
    if arr.ndim != 2:
        expected = f"(N, {dim})" if dim is not None else "(N, D)"
        raise ValueError(
            f"The '{name}' argument{where} must be a 2-D array of shape {expected}. "
            f"Got shape {arr.shape} instead."
        )
    if dim is not None and arr.shape[1] != dim:
        raise ValueError(
            f"The '{name}' argument{where} must have {dim} columns. Got shape {arr.shape} instead."
        )
    if arr.shape[0] < min_points:
        raise ValueError(
            f"The '{name}' argument{where} must have at least {min_points} point(s). "
            f"Got {arr.shape[0]} instead."
        )
    if not np.isfinite(arr).all():  # (the method: cheaper than np.all's dispatch)
        bad = int(np.count_nonzero(~np.isfinite(arr).all(axis=1)))
        raise ValueError(
            f"The '{name}' argument{where} must contain only finite values. "
            f"Got {bad} row(s) with NaN or infinity."
        )
    return np.ascontiguousarray(arr)


def check_scalar(
    value: Any,
    name: str,
    *,
    low: float | None = None,
    high: float | None = None,
    include_low: bool = False,
    include_high: bool = False,
    integer: bool = False,
    caller: str | None = None,
) -> float | int:
    """Check that ``value`` is a real (or integer) scalar inside an interval.

    Raises
    ------
    ValueError
        With a message such as "The 'kernel_width' parameter of register_nonrigid
        must be a float in (0, inf). Got -1 instead."
    """
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        ok = False
    elif integer and not isinstance(value, numbers.Integral):
        ok = False
    elif not _finite(value) and not (value == np.inf and high is None):
        ok = False
    else:
        ok = not (
            (low is not None and (value < low or (value == low and not include_low)))
            or (high is not None and (value > high or (value == high and not include_high)))
        )
    if not ok:  # the message only when needed: this check runs in every frame's loop
        where = f" of {caller}" if caller else ""
        kind = "an int" if integer else "a float"
        lo = "-inf" if low is None else f"{low:g}"
        hi = "inf" if high is None else f"{high:g}"
        interval = f"{'[' if include_low else '('}{lo}, {hi}{']' if include_high else ')'}"
        raise ValueError(
            f"The '{name}' parameter{where} must be {kind} in {interval}. Got {value!r} instead."
        )
    return int(value) if integer else float(value)


def _finite(value: numbers.Real) -> bool:
    """``np.isfinite(value)``; a float's by ``math`` (the ufunc costs 20 times more)."""
    return math.isfinite(value) if isinstance(value, float) else bool(np.isfinite(value))


def check_rng(rng: int | np.random.Generator | None) -> np.random.Generator:
    """Return a Generator from a seed, a Generator, or None."""
    if isinstance(rng, np.random.Generator):
        return rng
    if rng is None or isinstance(rng, numbers.Integral):
        return np.random.default_rng(rng)
    raise ValueError(
        f"The 'rng' argument must be an int, a numpy.random.Generator or None. "
        f"Got {type(rng).__name__} instead."
    )
