"""Side view of a person too near the camera: cut-off shanks with and without their exits.

Renders the built-in motion 1.6 m from a 320 x 240 Kinect (the shanks leave the image at
its lower edge), tracks it, and at a few frames fits the skeleton stage to the tracker's
own points and labels twice: with the parts that leave the image (``exits``, as the
tracker does) and without (the pushed-back stub's mode), beside the ground truth. The
side view (depth against height) shows what a frontal picture hides: without the exits
the shanks lean away from the camera. Ground truth is read here, never by the method.

Usage::

    OMP_NUM_THREADS=1 python benchmarks/cut_limbs_figure.py docs/images/cut_limbs.png
"""

from __future__ import annotations

import argparse

import numpy as np

from posedrift.skeleton import JOINT_PARENTS, joint_angles
from posedrift.skeleton._fit import fit_skeleton, image_exits
from posedrift.skeleton._meanshift import part_modes
from posedrift.synthetic import build_sequence, procedural_motion
from posedrift.tracking import PoseTracker

KNEES = slice(4, 6)  # left and right knee in ANGLE_NAMES


def fits(tracker: PoseTracker, result) -> dict[str, np.ndarray]:
    """The skeleton stage on one frame's points and labels, with and without the exits."""
    from posedrift.labelling import geodesic_graph

    cal = tracker.calibration
    points, labels = result.points, result.labels
    graph = geodesic_graph(points)
    options = {
        "bone_lengths": cal.bone_lengths,
        "edges": (graph.rows, graph.cols),
        "modes": part_modes(points, labels, bandwidth=0.06),
        "height": cal.height,
        "shoulder_offset": cal.shoulders,
    }
    exits = image_exits(points, labels, tracker.intrinsics, voxel_size=tracker._voxel)
    return {
        "without exits": fit_skeleton(points, labels, **options).joints,
        "with exits": fit_skeleton(points, labels, exits=exits, **options).joints,
    }


def main() -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("out", help="PNG to write")
    parser.add_argument("--frames", type=int, nargs="+", default=[20, 60, 120])
    parser.add_argument("--distance", type=float, default=1.6)
    args = parser.parse_args()
    seq = build_sequence(procedural_motion(), n_frames=max(args.frames) + 1, distance=args.distance)
    tracker = PoseTracker(seq.frames[0].intrinsics)
    results = [tracker.process(frame) for frame in seq.frames]
    edge_y = (tracker.intrinsics.height - 1 - tracker.intrinsics.cy) / tracker.intrinsics.fy
    panels = 2 * len(args.frames)
    fig, axes = plt.subplots(1, panels, figsize=(1.9 * panels, 5.0), sharey=True)
    for col, t in enumerate(args.frames):
        truth = seq.reference.joints[t]
        for k, (name, joints) in enumerate(fits(tracker, results[t]).items()):
            ax = axes[2 * col + k]
            for skeleton, style in ((truth, "g-"), (joints, "k-")):
                for j, p in enumerate(JOINT_PARENTS):
                    if p >= 0:
                        ax.plot(
                            skeleton[[j, p], 2],
                            -skeleton[[j, p], 1],
                            style,
                            lw=2 if style == "g-" else 1,
                        )
            depth = np.median(truth[:, 2])
            ax.axhline(-edge_y * depth, color="r", ls=":", lw=1)
            error = np.abs(joint_angles(joints) - seq.reference.angles[t])[KNEES].mean()
            ax.set_title(f"frame {t}\n{name}\nknees {error:.0f} degrees off", fontsize=8)
            ax.set_xlim(depth - 0.3, depth + 0.3)
            ax.set_aspect("equal")
            ax.set_xlabel("depth (m)")
    axes[0].set_ylabel("up from the camera's axis (m); red: the image's lower edge")
    fig.suptitle("green: truth, black: skeleton stage on the tracker's labels", fontsize=9)
    fig.tight_layout()
    fig.savefig(args.out, dpi=80)
    print(f"-> {args.out}")


if __name__ == "__main__":
    main()
