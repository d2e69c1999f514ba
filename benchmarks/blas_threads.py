"""The tracker with one BLAS thread against the library's own setting, alone and side by side.

``PoseTracker(blas_threads=1)`` (the default) limits the BLAS library to one thread
while it processes a frame; ``blas_threads=None`` leaves the library's setting (as many
threads as cores, unless ``OMP_NUM_THREADS`` says otherwise). This script tracks the
built-in motion in one process, then in as many processes side by side as the machine
has cores (several cameras, or a tracker beside other work), with each setting, and
prints each process's frames per second (wall clock over the tracking loop, rendering
excluded). Run it without ``OMP_NUM_THREADS`` set: that variable is what it compares
against.

Usage (about a minute on two cores)::

    python benchmarks/blas_threads.py --frames 300
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import time


def track(args: tuple[int, int | None, multiprocessing.Barrier]) -> float:
    """Frames per second of one tracker over the built-in motion."""
    frames, limit, start = args
    from posedrift.synthetic import build_sequence, procedural_motion
    from posedrift.tracking import PoseTracker

    sequence = build_sequence(procedural_motion(fps=30.0), n_frames=frames, in_place=True)
    tracker = PoseTracker(sequence.frames[0].intrinsics, blas_threads=limit)
    tracker.process(sequence.frames[0])  # loads the models
    start.wait()  # every process starts tracking at once
    begin = time.perf_counter()
    for frame in sequence.frames[1:]:
        tracker.process(frame)
    return (len(sequence.frames) - 1) / (time.perf_counter() - begin)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--repeats", type=int, default=2, help="runs of each setting")
    args = parser.parse_args(argv)
    if "OMP_NUM_THREADS" in os.environ or "OPENBLAS_NUM_THREADS" in os.environ:
        print("note: OMP_NUM_THREADS or OPENBLAS_NUM_THREADS is set: unset it to compare")
    cores = os.cpu_count() or 1
    print(f"{cores} cores; frames per second of each process (wall clock), {args.frames} frames")
    print("| BLAS threads | processes side by side | frames per second, each process |")
    print("|---|---:|---|")
    context = multiprocessing.get_context("spawn")
    for processes in sorted({1, cores}):
        for _ in range(args.repeats):
            for limit in (None, 1):
                manager = context.Manager()
                start = manager.Barrier(processes)
                with context.Pool(processes) as pool:
                    fps = pool.map(track, [(args.frames, limit, start)] * processes)
                manager.shutdown()
                label = "one (the default)" if limit == 1 else "the library's (None)"
                each = ", ".join(f"{f:.1f}" for f in fps)
                print(f"| {label} | {processes} | {each} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
