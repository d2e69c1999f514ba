"""BLAS threads for the per-frame work.

The tracker's matrices are small (400 points: the part net's four products of a few
hundred rows), and a BLAS library that splits each product over every core gains little
and collapses when the cores are busy: on a two-core machine one tracker alone ran at
116-118 frames per second with the library's two threads and 103-110 with one, but two
trackers side by side at 39-43 each with two threads and 101-106 with one
(``python benchmarks/blas_threads.py``; docs/RESULTS.md, speed section). One thread per
tracker keeps its speed whatever else runs: a second camera's tracker, a viewer, a
recorder.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextlib import AbstractContextManager
from functools import cache


@cache
def _controller():
    # Built once: inspecting the loaded libraries takes about 0.25 ms, limiting them
    # through a controller about 0.03 ms (a frame takes 10 ms).
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def blas_limited(limit: int | None) -> AbstractContextManager:
    """A context in which the BLAS libraries use at most ``limit`` threads (None: as set)."""
    if limit is None:
        return contextlib.nullcontext()
    return _controller().limit(limits=limit, user_api="blas")


@contextlib.contextmanager
def one_thread() -> Iterator[str]:
    """Every thread pool (BLAS and OpenMP) limited to one thread, for the benchmarks.

    Yields a line that says so, for the benchmarks' reports.
    """
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        yield "one thread (threadpoolctl limits=1)"
