"""Every output of the tracker on fixed renders, to check that a change alters none of them.

A speed-up of the per-frame loop should leave every frame's status, joints, confidences,
points and labels as they were, bit for bit. This script tracks fixed synthetic
sequences (the built-in motion and any BVH clips, rendered as ``posedrift bench track``
renders them) and saves those outputs; given ``--compare`` it also checks them against
a file saved by another checkout and names the first frame and field that differ.

Usage (about 5 s per 250-frame clip; run it at both commits, the second with
``--compare``; the exit status is 1 where anything differs)::

    OMP_NUM_THREADS=1 python benchmarks/track_fingerprint.py before.npz builtin \\
        ../shared/data/mocap/cmu/002_10.bvh --frames 250
    OMP_NUM_THREADS=1 python benchmarks/track_fingerprint.py after.npz builtin \\
        ../shared/data/mocap/cmu/002_10.bvh --frames 250 --compare before.npz
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from posedrift.benchmarks._track import render_sequences
from posedrift.camera import camera_preset
from posedrift.tracking import PoseTracker

FIELDS = ("joints", "confidence", "points", "labels")


def fingerprint(sources: list[str], frames: int, **scene) -> dict[str, np.ndarray]:
    """``{"clip|frame|field": array}`` of the tracker's outputs on each rendered clip
    (``scene``: :func:`render_sequences`' camera and room options)."""
    out = {}
    for source in sources:
        bvh = () if source == "builtin" else (source,)
        (sequence,) = render_sequences(bvh, frames=frames, **scene)
        tracker = PoseTracker(sequence.frames[0].intrinsics)
        for i, frame in enumerate(sequence.frames):
            result = tracker.process(frame)
            out[f"{sequence.name}|{i}|status"] = np.array(str(result.status))
            for field in FIELDS:
                out[f"{sequence.name}|{i}|{field}"] = np.asarray(getattr(result, field))
    return out


def differences(new: dict[str, np.ndarray], old) -> list[str]:
    """The keys whose arrays are not bit for bit the same (or are missing from either)."""

    def frame_order(key: str) -> tuple[str, int, str]:
        clip, frame, field = key.split("|")
        return clip, int(frame), field

    keys = sorted(set(new) | set(old.files), key=frame_order)
    return [
        key
        for key in keys
        if key not in new
        or key not in old.files
        or new[key].shape != old[key].shape
        or new[key].tobytes() != old[key].tobytes()
    ]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("out", help="where to save the outputs (.npz)")
    parser.add_argument("sources", nargs="*", default=["builtin"], help="builtin or BVH clips")
    parser.add_argument("--frames", type=int, default=250)
    parser.add_argument("--room", action="store_true", help="a floor, a wall and depth noise")
    parser.add_argument("--camera", help="a camera preset (default: Kinect v1 at 320 x 240)")
    parser.add_argument("--distance", type=float, help="metres from the camera")
    parser.add_argument("--compare", help="outputs saved by another checkout (.npz)")
    args = parser.parse_args(argv)
    camera = camera_preset(args.camera) if args.camera else None
    scene = {"room": args.room, "intrinsics": camera, "distance": args.distance}
    outputs = fingerprint(args.sources or ["builtin"], args.frames, **scene)
    np.savez(args.out, **outputs)
    print(f"{len(outputs)} arrays saved to {args.out}")
    if args.compare is None:
        return 0
    with np.load(args.compare) as old:
        changed = differences(outputs, old)
    if not changed:
        print(f"identical to {args.compare}, bit for bit")
        return 0
    print(f"{len(changed)} arrays differ from {args.compare}; the first: {changed[0]}")
    return 1


if __name__ == "__main__":
    sys.exit(main())
