"""CPD benchmark: posedrift against peer implementations, one process, identical inputs.

``run_cpd_benchmark(sizes, threads=..., repeats=..., rng=...)`` builds, per size, a
humanoid-shaped source (:func:`posedrift.points.sample_humanoid`), a smooth warp of it,
noise and 10% outliers, and times every implementation on the same arrays: median
wall and CPU (``time.process_time``) time, iterations, RMS error of the moved source to
the true warped positions, and peak memory (tracemalloc, which sees NumPy
allocations). It also measures a realistic frame-to-frame pair cold and warm-started.

Peers are imported lazily; a missing one is reported as skipped.
"""

from __future__ import annotations

import gc
import os
import platform
import statistics
import time
import tracemalloc
import warnings
from collections.abc import Callable, Sequence

import numpy as np

from posedrift._validation import check_rng
from posedrift.skeleton import JOINT_INDEX, t_pose_joints

BETA = 2.0
LAMBDA = 2.0
W = 0.1
TOL = 1e-5
MAX_ITER = 150


# --------------------------------------------------------------------------- inputs
def _rotation(axis, angle_rad: float) -> np.ndarray:
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * (k @ k)


def relaxed_pose_joints(height: float = 1.75) -> np.ndarray:
    """A T-pose with the arms lowered 45 degrees: the canonical benchmark pose."""
    j = t_pose_joints(height)
    for side, sign in (("right", -1.0), ("left", 1.0)):
        sh = j[JOINT_INDEX[f"{side}_shoulder"]]
        rot = _rotation([0, 0, 1], -sign * np.radians(45))
        for name in ("elbow", "hand"):
            idx = JOINT_INDEX[f"{side}_{name}"]
            j[idx] = sh + rot @ (j[idx] - sh)
    return j


def articulated_warp(
    points: np.ndarray, joints: np.ndarray, *, arm_deg: float, leg_deg: float, turn_deg: float
) -> np.ndarray:
    """A smooth articulated motion of a humanoid point set with known correspondences.

    Arms rotate ``arm_deg`` about the shoulders in the frontal plane (down for
    positive), legs ``leg_deg`` forward about the hips, with smooth (logistic) blending
    over a few centimetres at the joints; then the body turns ``turn_deg`` about +Y.
    """
    out = points.copy()
    pelvis = 0.5 * (joints[JOINT_INDEX["right_hip"]] + joints[JOINT_INDEX["left_hip"]])
    for side, sign in (("right", -1.0), ("left", 1.0)):
        sh = joints[JOINT_INDEX[f"{side}_shoulder"]]
        wgt = 1.0 / (1.0 + np.exp(-(sign * (points[:, 0] - sh[0]) + 0.02) / 0.015))
        wgt *= 1.0 / (1.0 + np.exp(-(points[:, 1] - (pelvis[1] + 0.15)) / 0.03))
        for i in np.nonzero(wgt > 1e-4)[0]:
            rot = _rotation([0, 0, 1], -sign * np.radians(arm_deg) * wgt[i])
            out[i] = sh + rot @ (points[i] - sh)
        hip = joints[JOINT_INDEX[f"{side}_hip"]]
        leg = 1.0 / (1.0 + np.exp((points[:, 1] - (hip[1] - 0.05)) / 0.03))
        leg *= 1.0 / (1.0 + np.exp(-(sign * points[:, 0] - 0.0) / 0.02))
        for i in np.nonzero(leg > 1e-4)[0]:
            rot = _rotation([1, 0, 0], -np.radians(leg_deg) * leg[i])
            out[i] = hip + rot @ (out[i] - hip)
    rot = _rotation([0, 1, 0], np.radians(turn_deg))
    return (out - pelvis) @ rot.T + pelvis


def make_problem(
    n_points: int,
    rng: int | np.random.Generator | None = 0,
    *,
    noise: float = 0.003,
    outlier_share: float = 0.1,
) -> dict[str, np.ndarray]:
    """Benchmark input: source, target (warped + noise + outliers), true warped source.

    Returns a dict with ``source`` (M, 3), ``target`` (N, 3), ``truth`` (M, 3) (the
    noise-free warped source: the true correspondences), metres.
    """
    from posedrift.points import sample_humanoid

    rng = check_rng(rng)
    joints = relaxed_pose_joints()
    source = sample_humanoid(joints, n_points, rng=rng)
    truth = articulated_warp(source, joints, arm_deg=12.0, leg_deg=8.0, turn_deg=6.0)
    bend = 0.02 * np.sin(2 * np.pi * truth[:, [1, 2, 0]] / 1.2)  # smooth 2 cm field
    truth = truth + bend
    target = truth + rng.normal(scale=noise, size=truth.shape)
    n_out = round(outlier_share * n_points)
    lo, hi = target.min(axis=0) - 0.1, target.max(axis=0) + 0.1
    outliers = rng.uniform(lo, hi, size=(n_out, 3))
    target = np.concatenate([target, outliers])
    target = target[rng.permutation(len(target))]
    return {"source": source, "target": target, "truth": truth}


def make_frame_pair(
    n_points: int, rng: int | np.random.Generator | None = 0, *, step_deg: float = 3.0
) -> dict[str, np.ndarray]:
    """Three consecutive frames a few degrees apart, resampled each frame.

    A dense canonical surface is posed at arm angles 0, ``step_deg``, ``2 step_deg``
    (legs and turn proportionally); each frame keeps its own random ``n_points`` of it
    plus 3 mm noise. Returns ``frames`` [(n, 3)] x 3 and ``truth12``: frame 1's points
    moved to frame 2 (true correspondences of the second registration).
    """
    from posedrift.points import sample_humanoid

    rng = check_rng(rng)
    joints = relaxed_pose_joints()
    dense = sample_humanoid(joints, 8 * n_points, rng=rng)
    posed = [
        articulated_warp(
            dense, joints, arm_deg=k * step_deg, leg_deg=k * step_deg / 2, turn_deg=k * step_deg / 2
        )
        for k in range(3)
    ]
    picks = [rng.choice(len(dense), size=n_points, replace=False) for _ in range(3)]
    frames = [posed[k][picks[k]] + rng.normal(scale=0.003, size=(n_points, 3)) for k in range(3)]
    return {"frames": frames, "truth12": posed[2][picks[1]]}


def rms(a: np.ndarray, b: np.ndarray) -> float:
    """Root-mean-square distance between corresponding rows."""
    return float(np.sqrt(np.mean(np.sum((a - b) ** 2, axis=1))))


# --------------------------------------------------------------------------- runners
def _run_posedrift(
    low_rank="auto", compiled=True, smoothness=LAMBDA, accelerate=True, dtype=np.float64
):
    """A runner of ``register_nonrigid``; the keyword defaults are its own defaults."""

    def run(source, target):
        from posedrift.registration import ConvergenceWarning, register_nonrigid

        with warnings.catch_warnings():
            warnings.simplefilter("ignore", ConvergenceWarning)
            res = register_nonrigid(
                source,
                target,
                kernel_width=BETA,
                smoothness=smoothness,
                outlier_weight=W,
                tol=TOL,
                max_iter=MAX_ITER,
                low_rank=low_rank,
                compiled=compiled,
                accelerate=accelerate,
                dtype=dtype,
            )
        return res.moved, res.iterations

    return run


def _run_pycpd(source, target):
    from pycpd import DeformableRegistration

    reg = DeformableRegistration(
        X=target, Y=source, alpha=LAMBDA, beta=BETA, w=W, tolerance=TOL, max_iterations=MAX_ITER
    )
    moved, _ = reg.register()
    return moved, reg.iteration


def _run_probreg(source, target):
    from probreg import cpd

    # probreg's kernel is exp(-d^2 / (2 beta)): its beta is our beta squared
    reg = cpd.NonRigidCPD(source, beta=BETA**2, lmd=LAMBDA, use_cuda=False)
    res = reg.registration(target, w=W, maxiter=MAX_ITER, tol=TOL)
    moved = res.transformation.transform(source)
    return np.asarray(moved), -1


def _run_rustcpd(low_rank=None, parallel=False):
    def run(source, target):
        import rustcpd

        res = rustcpd.register_deformable(
            target,
            source,
            alpha=LAMBDA,
            beta=BETA,
            low_rank=low_rank,
            normalize=True,
            max_iterations=MAX_ITER,
            tolerance=TOL,
            outlier_weight=W,
            parallel=parallel,
        )
        return np.asarray(res.points), int(res.iterations)

    return run


def _peer_available(module: str) -> str | None:
    """None when ``module`` is installed (found without importing it), else why not."""
    import importlib.util

    try:
        found = importlib.util.find_spec(module) is not None
    except (ImportError, ValueError) as exc:
        return f"{type(exc).__name__}: {exc}"
    return None if found else f"{module} is not installed"


def implementations(
    size: int, threads: int | None = 1
) -> dict[str, tuple[Callable | None, str | None]]:
    """Name -> (runner or None, skip reason or None) for one problem size."""
    impls: dict[str, tuple[Callable | None, str | None]] = {}
    exact = {"low_rank": None, "accelerate": False}
    dense_why = "exact dense solve above 3000 points"
    # "posedrift" is register_nonrigid's defaults (low_rank="auto", accelerate=True)
    impls["posedrift"] = (_run_posedrift(), None)
    impls["posedrift-float32"] = (_run_posedrift(dtype=np.float32), None)
    if size > 400:
        # CPD's regularizer weakens as M grows (G's eigenvalues grow with M): the same
        # prior strength as smoothness=2 at 400 points is 2 M / 400
        impls["posedrift-scaled-smoothness"] = (
            _run_posedrift(smoothness=LAMBDA * size / 400),
            None,
        )
    if size <= 3000:
        impls["posedrift-exact"] = (_run_posedrift(**exact), None)
        impls["posedrift-exact-accel"] = (_run_posedrift(None, accelerate=True), None)
        impls["posedrift-exact-numpy"] = (_run_posedrift(**exact, compiled=False), None)
    else:
        impls["posedrift-exact"] = (None, f"{dense_why}: see low_rank")
    impls["posedrift-lowrank100"] = (_run_posedrift(100, accelerate=False), None)
    why = _peer_available("pycpd")
    if why is None and size > 2000:
        gib = size * size * 1.1 * 3 * 8 / 2**30
        why = f"builds M x N x D temporaries ({gib:.1f} GiB each) and an O(M^3) solve"
    impls["pycpd"] = (_run_pycpd, None) if why is None else (None, why)
    why = _peer_available("probreg")
    if why is None and size > 2000:
        why = "dense M x N posterior and O(M^3) solve per iteration: minutes at this size"
    impls["probreg"] = (_run_probreg, None) if why is None else (None, why)
    why = _peer_available("rustcpd")
    parallel = threads != 1
    if why is None and size > 3000:
        impls["rustcpd"] = (None, "exact dense solve above 3000 points")
        impls["rustcpd-lowrank100"] = (None, "one run took 357 s at 10,000 points in development")
    else:
        impls["rustcpd"] = (_run_rustcpd(None, parallel), None) if why is None else (None, why)
        impls["rustcpd-lowrank100"] = (
            (_run_rustcpd(100, parallel), None) if why is None else (None, why)
        )
    impls["cpd-pytorch"] = (None, "needs torch (forbidden on this project)")
    return impls


def _measure(run, source, target, truth, repeats, first=None):
    """Median of ``repeats`` timed runs (or the single run ``first`` = (time, output))."""
    times, cpu, moved, iters = [], [], None, -1
    if first is not None:
        times, cpu, (moved, iters) = [first[0]], [first[1]], first[2]
        repeats = 0
    for _ in range(repeats):
        gc.collect()
        t0, c0 = time.perf_counter(), time.process_time()
        moved, iters = run(source, target)
        cpu.append(time.process_time() - c0)
        times.append(time.perf_counter() - t0)
    gc.collect()
    tracemalloc.start()
    run(source, target)
    _, peak = tracemalloc.get_traced_memory()
    tracemalloc.stop()
    return {
        "median_s": statistics.median(times),
        "min_s": min(times),
        "cpu_median_s": statistics.median(cpu),
        "repeats": len(times),
        "iterations": int(iters),
        "rms_m": rms(np.asarray(moved), truth),
        "peak_mib": peak / 2**20,
    }


def _thread_limits(threads: int | None):
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=threads)


FRAME_CONFIGS = {
    # name: options of register_nonrigid beyond the benchmark's beta, lambda, w
    "": {"tol": TOL},  # the defaults (low_rank="auto", accelerate=True): "cold", "warm"
    "float32": {"tol": TOL, "dtype": np.float32},
    "tol1e-4": {"tol": 1e-4},
    "exact": {"low_rank": None, "accelerate": False, "tol": TOL},
    "lowrank100": {"low_rank": 100, "accelerate": False, "tol": TOL},
}


def frame_to_frame(
    n_points: int = 400, *, repeats: int = 5, rng=0, configs: Sequence[str] | None = None
) -> dict:
    """Cold vs warm-started registration of consecutive frames (the tracker's case).

    Three frames of :func:`make_frame_pair`; the first pair is registered with the
    same options, the second pair cold and warm-started from the first result. For
    each configuration of :data:`FRAME_CONFIGS` (all by default) the keys ``cold_<name>``
    and ``warm_<name>`` (``cold`` and ``warm`` for the defaults) hold median wall and
    CPU (``time.process_time``) seconds, iterations and RMS to the true positions.
    """
    from posedrift.registration import ConvergenceWarning, register_nonrigid

    pair = make_frame_pair(n_points, rng)
    f0, f1, f2 = pair["frames"]
    base = dict(kernel_width=BETA, smoothness=LAMBDA, outlier_weight=W, max_iter=MAX_ITER)
    out = {}
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        for name in FRAME_CONFIGS if configs is None else configs:
            kw = {**base, **FRAME_CONFIGS[name]}
            prev = register_nonrigid(f0, f1, **kw)
            for mode in ("cold", "warm"):
                ws = prev if mode == "warm" else None
                times, cpu = [], []
                res = None
                for _ in range(repeats):
                    t0, c0 = time.perf_counter(), time.process_time()
                    res = register_nonrigid(f1, f2, warm_start=ws, **kw)
                    cpu.append(time.process_time() - c0)
                    times.append(time.perf_counter() - t0)
                out[f"{mode}_{name}" if name else mode] = {
                    "median_s": statistics.median(times),
                    "cpu_median_s": statistics.median(cpu),
                    "iterations": res.iterations,
                    "rms_m": rms(res.moved, pair["truth12"]),
                }
    out["no_motion_rms_m"] = rms(f1, pair["truth12"])
    out["points"] = n_points
    return out


def machine_info() -> dict:
    """CPU model, logical cores, Python and NumPy versions."""
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return {
        "cpu": cpu,
        "logical_cores": os.cpu_count(),
        "python": platform.python_version(),
        "numpy": np.__version__,
    }


def run_cpd_benchmark(
    sizes: Sequence[int] = (400, 2000, 10000),
    *,
    threads: Sequence[int | None] = (1, None),
    repeats: int = 5,
    rng: int | np.random.Generator | None = 0,
    progress: Callable[[str], None] | None = None,
    frame_points: int = 400,
    only: Sequence[str] | None = None,
) -> dict:
    """Run posedrift and its peers on identical inputs; return a JSON-ready dict.

    Parameters
    ----------
    sizes : sequence of int
        Source sizes M (the target has 1.1 M points with the outliers).
    threads : sequence of int or None
        Thread limits to run under (threadpoolctl); None means all threads.
    repeats : int
        Timed repeats per implementation and size (median reported). Slow peers
        (over 5 s per run) are timed once.
    rng : int, numpy.random.Generator or None
        Seed of the inputs.
    progress : callable, optional
        Called with a short message before each measurement.
    frame_points : int
        Points per frame of the cold vs warm frame-to-frame measurement.
    only : sequence of str, optional
        Run only these implementations (names as in the report); default all.

    Returns
    -------
    dict
        ``{"machine", "parameters", "results": [{"size", "threads", "impl", ...}],
        "frame_to_frame": {...}}``.
    """
    from posedrift.registration._estep import has_compiled_kernel

    rng = check_rng(rng)
    results = []
    problems = {int(s): make_problem(int(s), rng) for s in sizes}
    for thr in threads:
        limiter = _thread_limits(thr)
        try:
            for size, prob in problems.items():
                for name, (run, why) in implementations(size, thr).items():
                    if only is not None and name not in only:
                        continue
                    row = {
                        "size": size,
                        "n_target": len(prob["target"]),
                        "threads": thr or os.cpu_count(),
                        "impl": name,
                    }
                    if run is None:
                        results.append({**row, "skipped": why})
                        continue
                    if progress:
                        progress(f"{name} M={size} threads={row['threads']}")
                    t0, c0 = time.perf_counter(), time.process_time()
                    try:
                        out = run(prob["source"], prob["target"])  # warm-up (imports, caches)
                    except Exception as exc:  # a broken peer is reported, not fatal
                        results.append({**row, "skipped": f"{type(exc).__name__}: {exc}"})
                        continue
                    once, once_cpu = time.perf_counter() - t0, time.process_time() - c0
                    # a slow run (over 5 s) is timed once: its warm-up is the measurement
                    first = (once, once_cpu, out) if once > 5.0 else None
                    src, tgt, truth = prob["source"], prob["target"], prob["truth"]
                    results.append({**row, **_measure(run, src, tgt, truth, repeats, first)})
        finally:
            if limiter is not None:
                limiter.unregister()
    f2f_limiter = _thread_limits(1)
    try:
        if progress:
            progress(f"frame-to-frame cold/warm, {frame_points} points, 1 thread")
        f2f = frame_to_frame(frame_points, repeats=repeats, rng=rng)
    finally:
        if f2f_limiter is not None:
            f2f_limiter.unregister()
    return {
        "machine": machine_info(),
        "compiled_estep": has_compiled_kernel(),
        "parameters": {
            "kernel_width": BETA,
            "smoothness": LAMBDA,
            "outlier_weight": W,
            "tol": TOL,
            "max_iter": MAX_ITER,
            "noise_m": 0.003,
            "outlier_share": 0.1,
        },
        "truth_motion_rms_m": {str(s): rms(p["source"], p["truth"]) for s, p in problems.items()},
        "results": results,
        "frame_to_frame": f2f,
    }


def markdown_table(report: dict) -> str:
    """The results as a Markdown table."""
    lines = [
        "| size M | threads | implementation | median wall (s) | median CPU (s) | iterations "
        "| RMS (mm) | peak memory (MiB) |",
        "|---:|---:|---|---:|---:|---:|---:|---:|",
    ]
    for r in report["results"]:
        if "skipped" in r:
            lines.append(
                f"| {r['size']} | {r['threads']} | {r['impl']} | skipped: {r['skipped']} | | | | |"
            )
            continue
        it = r["iterations"] if r["iterations"] >= 0 else "n/a"
        lines.append(
            f"| {r['size']} | {r['threads']} | {r['impl']} | {r['median_s']:.4f} | "
            f"{r.get('cpu_median_s', float('nan')):.4f} | {it} | "
            f"{1000 * r['rms_m']:.2f} | {r['peak_mib']:.1f} |"
        )
    f2f = report.get("frame_to_frame")
    if f2f:
        lines += [
            "",
            f"Frame to frame ({f2f['points']} points, consecutive poses 3 degrees apart, "
            "1 thread; "
            f"no-motion RMS {1000 * f2f['no_motion_rms_m']:.1f} mm):",
            "",
            "| start_config | median wall (ms) | median CPU (ms) | iterations | RMS (mm) |",
            "|---|---:|---:|---:|---:|",
        ]
        for mode, r in f2f.items():
            if not isinstance(r, dict):
                continue
            lines.append(
                f"| {mode} | {1000 * r['median_s']:.2f} | "
                f"{1000 * r.get('cpu_median_s', float('nan')):.2f} | {r['iterations']} | "
                f"{1000 * r['rms_m']:.2f} |"
            )
    return "\n".join(lines) + "\n"
