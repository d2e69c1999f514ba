"""Frame-to-frame CPD under the tracker's settings: iterations, time, RMS, labels.

The tracker (``posedrift.tracking.PoseTracker``) registers the previous frame's 400
points onto the current frame's with ``kernel_width=0.5, smoothness=1,
outlier_weight=0.05, tol=1e-4``, warm-started with sigma at least 2 cm (here
``max_iter=40``).
This script times that call on three frame pairs of ``make_frame_pair`` (seeds 0-2)
for several ``register_nonrigid`` options and compares each result with the exact,
plain-EM one: RMS between the moved sets and agreement of the labels moved by
``transfer_labels`` (label = nearest joint of each source point). The tracker itself
passes ``low_rank=60, accelerate=True``.

Usage: OMP_NUM_THREADS=1 OPENBLAS_NUM_THREADS=1 python benchmarks/cpd_tracker_settings.py
"""

from __future__ import annotations

import dataclasses
import time
import warnings

import numpy as np
from threadpoolctl import threadpool_limits

from posedrift.benchmarks._cpd import make_frame_pair, relaxed_pose_joints, rms
from posedrift.registration import ConvergenceWarning, register_nonrigid

BASE = dict(kernel_width=0.5, smoothness=1.0, outlier_weight=0.05, max_iter=40, tol=1e-4)
CONFIGS = {
    # the first is the reference ("current") of the last two columns
    "exact, plain EM": {"low_rank": None, "accelerate": False},
    "exact + accelerate": {"low_rank": None},
    "low_rank=60 + accelerate (tracker now)": {"low_rank": 60},
    "defaults (low_rank='auto' + accelerate)": {},
    "low_rank=100 + accelerate": {"low_rank": 100},
}


def main(repeats: int = 5) -> None:
    joints = relaxed_pose_joints()
    print(
        "| seed | options | M-steps | wall (ms) | CPU (ms) | RMS to truth (mm) "
        "| RMS to current (mm) | labels as current |"
    )
    print("|---:|---|---:|---:|---:|---:|---:|---:|")
    for seed in (0, 1, 2):
        pair = make_frame_pair(400, seed)
        f0, f1, f2 = pair["frames"]
        labels = np.argmin(np.linalg.norm(f1[:, None] - joints[None], axis=2), axis=1)
        ref = None
        for name, opts in CONFIGS.items():
            kw = {**BASE, **opts}
            prev = register_nonrigid(f0, f1, **kw)
            prev = dataclasses.replace(prev, sigma2=max(prev.sigma2, 0.02**2))
            walls, cpus = [], []
            for _ in range(repeats):
                t0, c0 = time.perf_counter(), time.process_time()
                res = register_nonrigid(f1, f2, warm_start=prev, **kw)
                cpus.append(time.process_time() - c0)
                walls.append(time.perf_counter() - t0)
            lab = res.transfer_labels(labels, 15).argmax(axis=1)
            if ref is None:
                ref = (res.moved, lab)
            print(
                f"| {seed} | {name} | {res.iterations} | {1e3 * np.median(walls):.1f} | "
                f"{1e3 * np.median(cpus):.1f} | {1e3 * rms(res.moved, pair['truth12']):.1f} | "
                f"{1e3 * rms(res.moved, ref[0]):.1f} | {np.mean(lab == ref[1]):.4f} |"
            )


if __name__ == "__main__":
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", ConvergenceWarning)
        with threadpool_limits(1):
            main()
