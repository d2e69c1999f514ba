"""The tracker's compiled CPD kernels against their NumPy twins, one core.

Each frame the tracker carries its labels over by CPD's posterior: for each of the
frame's points, the posterior mass of each part's template points
(``posterior_label_mass``), about 400 x 400 kernel values. The NumPy twin spends most of
its time in float64 ``exp``, which NumPy vectorizes only with AVX-512; the compiled
kernel has its own vectorized exponential, cloned for AVX-512, AVX2 (without FMA) and
plain x86-64, and, as the tracker calls it, sums only the template points within the
truncation half-width of each point along the longest axis (every entry exact to
1e-12). This prints the median milliseconds of each, of the E-step (float64 and
float32) beside them, and of NumPy's ``exp`` on the same number of values in float64 and
float32, with the processor's vector level.

Usage: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/bench_kernels.py
"""

from __future__ import annotations

import timeit

import numpy as np

from posedrift.benchmarks._track import simd_level
from posedrift.registration import _estep


def median_ms(fn, number: int = 50, repeat: int = 7) -> float:
    return 1e3 * float(np.median(timeit.repeat(fn, number=number, repeat=repeat))) / number


def main(points: int = 400, sigma2: float = 4e-4, outlier: float = 0.01) -> None:
    rng = np.random.default_rng(0)
    target = 0.3 * rng.normal(size=(points, 3))  # metres, about a body's spread
    moved = target + 0.01 * rng.normal(size=(points, 3))
    labels = rng.integers(0, 15, points)
    compiled = _estep.posterior_label_mass(target, moved, sigma2, outlier, labels, 15)
    twin = _estep.posterior_label_mass(target, moved, sigma2, outlier, labels, 15, compiled=False)
    values = -50.0 * rng.random((points, points))
    values32 = values.astype(np.float32)
    print(
        f"{points} x {points} points, {simd_level()}, compiled kernel built: "
        f"{_estep.has_compiled_kernel()}; largest difference {np.abs(compiled - twin).max():.1e}"
    )
    print("| what | ms |\n|---|---:|")
    eps = _estep.TRUNCATE_EPS
    for name, fn in [
        (
            "label transfer, compiled, truncated (the tracker's)",
            lambda: _estep.posterior_label_mass(
                target, moved, sigma2, outlier, labels, 15, truncate_eps=eps
            ),
        ),
        (
            "label transfer, compiled, every pair",
            lambda: _estep.posterior_label_mass(target, moved, sigma2, outlier, labels, 15),
        ),
        (
            "label transfer, NumPy twin",
            lambda: _estep.posterior_label_mass(
                target, moved, sigma2, outlier, labels, 15, compiled=False
            ),
        ),
        ("E-step, compiled, float64", lambda: _estep.estep_stats(target, moved, sigma2, outlier)),
        (
            "E-step, compiled, float32",
            lambda: _estep.estep_stats(target, moved, sigma2, outlier, single=True),
        ),
        (
            "E-step, NumPy twin, float64",
            lambda: _estep.estep_stats(target, moved, sigma2, outlier, compiled=False),
        ),
        ("np.exp, float64", lambda: np.exp(values)),
        ("np.exp, float32", lambda: np.exp(values32)),
    ]:
        print(f"| {name} | {median_ms(fn):.3f} |")


if __name__ == "__main__":
    main()
