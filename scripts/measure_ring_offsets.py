"""Measure where the part boundaries lie from the front and from behind (``RING_BACK_RADII``).

Usage::

    python scripts/measure_ring_offsets.py
    python scripts/measure_ring_offsets.py --clips builtin,002_01 --mocap ../shared/data/mocap/cmu

The skeleton stage places a ring joint (knee, hip, elbow...) at the centre of the boundary
between its two parts, pushed back along the camera ray by a radius
(``posedrift.skeleton._fit.RING_JOINTS``). Those radii were set on people facing the
camera. This renders clips facing the camera and turned away from it
(``build_sequence(facing=180)``), labels the downsampled points with their *true* parts,
and prints, per ring joint, the median distance along the ray from the boundary's centre
to the true joint, front and back, with the back radius that distance implies: the front
radius shifted by the difference, at a 1.75 m stature (the clips' scale); and for the
elbows and knees the distance down the limb (``ELBOW_BOUNDARY_SHIFT``). It reads ground
truth, so it lives here and not in the method.

The default clips are among those the forest trains on and none of the held-out ones
(``007_*``, ``131_03``), so the held-out figure in docs/RESULTS.md scores the radii on
motion they were not measured on. The figures in use came from this script's defaults
with ``--frames 500 --every 3`` (about 20 s).
"""

from __future__ import annotations

import argparse
from collections import defaultdict
from pathlib import Path

import numpy as np

from posedrift.camera import backproject, project
from posedrift.labelling import geodesic_graph
from posedrift.points import downsample
from posedrift.skeleton import JOINT_INDEX, PART_INDEX
from posedrift.skeleton._fit import RING_BACK_RADII, RING_JOINTS, part_boundaries
from posedrift.synthetic import build_sequence, bvh_motion, procedural_motion

_FRONT, _BACK = 0.0, 180.0
# Joints whose boundary also lies along the limb: measured from the joint named here.
_DOWN_THE_LIMB = {
    f"{side}_{joint}": f"{side}_{parent}"
    for side in ("right", "left")
    for joint, parent in (("elbow", "shoulder"), ("knee", "hip"))
}


def _point_labels(depth: np.ndarray, truth: np.ndarray, intrinsics, n_points: int, rng: int):
    """The person's points downsampled as the tracker does, each with its pixel's true part."""
    points, _ = backproject(depth, intrinsics, depth > 0)
    points = downsample(points, n_points, rng=rng)
    uv = np.rint(project(points, intrinsics)).astype(int)
    rows = np.clip(uv[:, 1], 0, depth.shape[0] - 1)
    cols = np.clip(uv[:, 0], 0, depth.shape[1] - 1)
    return points, truth[rows, cols].astype(int) - 1  # the rendered labels count from 1


def ray_offsets(motion, facing: float, *, frames: int, every: int, n_points: int) -> dict:
    """Per ring joint, the along-ray distances (metres) from boundary centre to joint."""
    seq = build_sequence(motion, n_frames=frames, in_place=True, facing=facing, rng=0)
    offsets: dict[str, list[float]] = defaultdict(list)
    for t in range(every // 2, len(seq.frames), every):
        frame = seq.frames[t]
        if np.count_nonzero(frame.depth > 0) < 100:
            continue
        points, labels = _point_labels(
            frame.depth, seq.reference.labels[t], frame.intrinsics, n_points, t
        )
        graph = geodesic_graph(points)
        centres, counts = part_boundaries(points, labels, graph.rows, graph.cols)
        joints = seq.reference.joints[t]
        for name, (a, b, _) in RING_JOINTS.items():
            pa, pb = PART_INDEX[a], PART_INDEX[b]
            if counts[pa, pb] < 2:
                continue
            centre = centres[pa, pb]
            ray = centre / np.linalg.norm(centre)
            joint = joints[JOINT_INDEX[name]]
            offsets[name].append(float((joint - centre) @ ray))
            if name in _DOWN_THE_LIMB:  # How far the joint lies beyond its boundary.
                bone = joint - joints[JOINT_INDEX[_DOWN_THE_LIMB[name]]]
                down = float((joint - centre) @ bone) / np.linalg.norm(bone)
                offsets[f"{name} down"].append(down)
    return offsets


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--clips", default="builtin,002_01,003_01,001_14")
    parser.add_argument("--mocap", default="../shared/data/mocap/cmu", type=Path)
    parser.add_argument("--frames", type=int, default=160)
    parser.add_argument("--every", type=int, default=6, help="use one frame in this many")
    parser.add_argument("--points", type=int, default=400)
    args = parser.parse_args()
    pooled = {_FRONT: defaultdict(list), _BACK: defaultdict(list)}
    for clip in args.clips.split(","):
        if clip == "builtin":
            motion = procedural_motion(fps=30.0)
        else:
            path = args.mocap / f"{clip}.bvh"
            if not path.is_file():
                raise SystemExit(f"{path}: no such file (--mocap names the CMU clips' folder)")
            motion = bvh_motion(path)
        for facing, table in pooled.items():
            found = ray_offsets(
                motion, facing, frames=args.frames, every=args.every, n_points=args.points
            )
            for name, values in found.items():
                table[name].extend(values)
        print(f"{clip}: done", flush=True)
    print(f"\n{'joint':10s} {'front mm':>9s} {'back mm':>8s} {'radius':>7s} "
          f"{'implied back':>13s} {'in use':>7s}")  # fmt: skip
    for name, (_, _, radius) in RING_JOINTS.items():
        if name.startswith("left_"):
            continue  # the body is symmetric: each side pooled with the other
        kind = name.removeprefix("right_")
        names = {name, name.replace("right_", "left_")}
        front, back = (
            1e3 * np.median([v for n in names for v in pooled[view][n]] or [np.nan])
            for view in (_FRONT, _BACK)
        )
        implied = radius + 1e-3 * (back - front)
        print(f"{kind:10s} {front:9.0f} {back:8.0f} {radius:7.4f} {implied:13.4f} "
              f"{RING_BACK_RADII[name]:7.3f}")  # fmt: skip
    print("\nDown the limb, from the boundary's centre to the joint (mm; front, back): "
          "the elbow's is ELBOW_BOUNDARY_SHIFT, the knee's the offset in ring_joints.")  # fmt: skip
    for name in ("right_elbow", "right_knee"):
        names = {f"{name} down", f"{name} down".replace("right_", "left_")}
        front, back = (
            1e3 * np.median([v for n in names for v in pooled[view][n]] or [np.nan])
            for view in (_FRONT, _BACK)
        )
        print(f"{name.removeprefix('right_'):10s} {front:9.0f} {back:8.0f}")


if __name__ == "__main__":
    main()
