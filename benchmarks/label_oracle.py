"""How much of the tracker's angle error do its labels cause? A perfect-label control.

For each synthetic clip this runs the tracker (``PoseTracker``, depth and intrinsics
only) and, on the same frames, the same skeleton stage fed the *true* part labels:
the frame's person pixels back-projected and downsampled as the tracker does, each
point given the label of its nearest pixel, then mean shift and ``fit_skeleton``
with the tracker's own calibration (stature and bone lengths), frame by frame with
no temporal prediction. The control reads ground truth, so it lives here, beside
the method, never in it: it bounds what better labels alone could give, and its
first / last 100-frame ratio measures how much harder the end of a clip is than its
beginning (the drift target compares those windows). A third row runs the whole tracker
with a *perfect forest* (:class:`TrueLabelForest`: each pixel's true part at
probability 0.9), which separates what the forest's mistakes cost from what the
tracking loop itself (registration, relabelling, health checks, filling hidden
joints) costs. Where the true labels leave a
joint unplaced (a limb hidden in a side view), its angles are left out of the means;
the last column says what share of the angles was scored. A second table gives each
angle's mean error, rows as in the first, and a third the same over the angles whose
joints the frames show (:func:`posedrift.evaluation.angles_seen`: in the image and hidden
by nothing), where no labeller can be blamed for what the camera does not see.

Usage (about 10 s per 500-frame clip; ``--height`` and ``--girth`` render another body)::

    OMP_NUM_THREADS=1 python benchmarks/label_oracle.py builtin \\
        ../shared/data/mocap/cmu/002_07.bvh --frames 500 [--height 1.55 --girth 1.15]
"""

from __future__ import annotations

import argparse
import warnings

import numpy as np
from scipy.spatial import cKDTree

from posedrift.camera import backproject
from posedrift.evaluation import VIEWS, angles_seen, facing_by_view
from posedrift.labelling import PartPrediction
from posedrift.labelling._relabel import geodesic_graph
from posedrift.points import downsample
from posedrift.skeleton import ANGLE_NAMES, facing_yaw, joint_angles
from posedrift.skeleton._fit import fit_skeleton, image_exits
from posedrift.skeleton._meanshift import part_modes
from posedrift.synthetic import build_sequence, bvh_motion, procedural_motion
from posedrift.tracking import PoseTracker

N_PARTS = 15


class TrueLabelForest:
    """A body-part forest that answers with the current frame's true labels (a control).

    Set :attr:`truth` to the frame's label image (part index + 1, 0 background)
    before each ``process`` call; probabilities are 0.9 on the true part.
    """

    def __init__(self) -> None:
        self.truth: np.ndarray | None = None

    def _probabilities(self, parts: np.ndarray) -> np.ndarray:
        out = np.full((len(parts), N_PARTS), 0.1 / (N_PARTS - 1), dtype=np.float32)
        known = parts >= 0
        out[np.flatnonzero(known), parts[known]] = 0.9
        out[~known] = 1.0 / N_PARTS
        return out

    def predict(self, depth, mask, intrinsics) -> PartPrediction:
        labels = np.where(mask, self.truth.astype(np.int16) - 1, -1).astype(np.int16)
        pixels = np.argwhere(labels >= 0)
        parts = labels[pixels[:, 0], pixels[:, 1]].astype(np.int64)
        return PartPrediction(labels, pixels, self._probabilities(parts))

    def predict_pixels(self, depth, pixels, intrinsics, *, mask=None) -> np.ndarray:
        pixels = np.asarray(pixels)
        return self._probabilities(self.truth[pixels[:, 0], pixels[:, 1]].astype(np.int64) - 1)


def tracked_joints(sequence, tracker: PoseTracker, forest: TrueLabelForest | None = None):
    """``(T, 15, 3)`` joints of the tracker, frame by frame (``forest`` fed the truth)."""
    joints = []
    for t, frame in enumerate(sequence.frames):
        if forest is not None:
            forest.truth = sequence.reference.labels[t]
        joints.append(tracker.process(frame).joints)
    return np.stack(joints)


def true_label_joints(sequence, calibration, n_points: int = 400) -> np.ndarray:
    """``(T, 15, 3)`` joints of the skeleton fitted to each frame's true labels."""
    out = np.full((len(sequence.frames), 15, 3), np.nan)
    for t, frame in enumerate(sequence.frames):
        truth = sequence.reference.labels[t]
        mask = (truth > 0) & (frame.depth > 0)
        if mask.sum() < 60:
            continue
        full, pixels = backproject(frame.depth, frame.intrinsics, mask)
        points, voxel = downsample(full, n_points, rng=0, return_voxel_size=True)
        _, nearest = cKDTree(full).query(points)
        labels = truth[pixels[nearest, 0], pixels[nearest, 1]].astype(np.int64) - 1
        graph = geodesic_graph(points)
        fit = fit_skeleton(
            points,
            labels,
            bone_lengths=calibration.bone_lengths,
            edges=(graph.rows, graph.cols),
            modes=part_modes(points, labels, bandwidth=0.06),
            height=calibration.height,
            shoulder_offset=calibration.shoulders,
            exits=image_exits(points, labels, frame.intrinsics, voxel_size=voxel),
        )
        out[t] = fit.joints
    return out


def summary(errors: np.ndarray, yaw: np.ndarray) -> dict[str, float]:
    """Mean error, first / last 100 frames and per view, of ``(T,)`` per-frame errors."""
    row = {"mean": np.nanmean(errors)}
    row["first 100"], row["last 100"] = np.nanmean(errors[:100]), np.nanmean(errors[-100:])
    row["last/first"] = row["last 100"] / row["first 100"]
    for view, (low, high) in VIEWS.items():
        inside = (yaw >= low) & (yaw < high)
        row[view] = np.nanmean(errors[inside]) if inside.any() else np.nan
    return row


def facing_cells(joints: np.ndarray, reference: np.ndarray) -> str:
    """The median facing yaw of ``joints`` per view, the reference's in brackets."""
    cells = []
    for own, truth in facing_by_view(joints, reference).values():
        cells.append("-" if own is None else f"{own:.0f} ({truth:.0f})")
    return " / ".join(cells)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("clips", nargs="+", help="BVH files, or 'builtin'")
    parser.add_argument("--frames", type=int, default=500)
    parser.add_argument("--height", type=float, default=None, help="body stature, metres")
    parser.add_argument("--girth", type=float, default=1.0, help="body girth factor")
    args = parser.parse_args()
    shape = {"girth": args.girth} if args.girth != 1.0 else None
    columns = ["mean", "first 100", "last 100", "last/first", *VIEWS]
    views = " / ".join(VIEWS)
    print(
        "| clip | labels | " + " | ".join(columns) + " | angles scored "
        f"| facing yaw, {views} (truth) |"
    )
    print("|---|---|" + "---:|" * (len(columns) + 2))
    per_angle = []  # (clip, labels, (8,) mean error of each angle)
    per_angle_seen = []  # the same over the angles the frames show
    n_seen = n_angles = 0
    for clip in args.clips:
        motion = procedural_motion(fps=30.0) if clip == "builtin" else bvh_motion(clip)
        sequence = build_sequence(
            motion,
            n_frames=args.frames,
            in_place=True,
            shape=shape,
            stature=args.height,
            rng=0,
            name=clip,
        )
        tracker = PoseTracker(sequence.frames[0].intrinsics)
        tracked = tracked_joints(sequence, tracker)
        oracle = true_label_joints(sequence, tracker.calibration)
        perfect = TrueLabelForest()
        # decimation=1: the true label image is at the frame's own resolution.
        with_truth = tracked_joints(
            sequence,
            PoseTracker(sequence.frames[0].intrinsics, forest=perfect, decimation=1),
            perfect,
        )
        yaw = facing_yaw(sequence.reference.joints)
        seen = angles_seen(
            sequence.reference.joints,
            [f.depth for f in sequence.frames],
            sequence.frames[0].intrinsics,
        )
        n_seen, n_angles = n_seen + int(seen.sum()), n_angles + seen.size
        name = clip.rsplit("/", 1)[-1]
        rows = (("tracker", tracked), ("tracker, perfect forest", with_truth), ("true", oracle))
        for kind, joints in rows:
            angles = joint_angles(joints)
            angle_errors = np.abs(angles - sequence.reference.angles)
            errors = np.nanmean(angle_errors, axis=1)
            row = summary(errors, yaw)
            cells = " | ".join(f"{row[c]:.2f}" for c in columns)
            # Angles whose joints the labels could not place are left out of the means
            # (NaN), which flatters a skeleton stage that gives up on hard frames.
            scored = np.mean(np.isfinite(angles))
            print(
                f"| {name} | {kind} | {cells} | {100 * scored:.0f}% "
                f"| {facing_cells(joints, sequence.reference.joints)} |",
                flush=True,
            )
            per_angle.append((name, kind, np.nanmean(angle_errors, axis=0)))
            with warnings.catch_warnings():  # an angle never seen in a clip: NaN
                warnings.simplefilter("ignore", RuntimeWarning)
                seen_errors = np.nanmean(np.where(seen, angle_errors, np.nan), axis=0)
            per_angle_seen.append((name, kind, seen_errors))
    print_per_angle(per_angle)
    print(f"\nOver the angles whose joints the frames show ({100 * n_seen / n_angles:.1f}%):")
    print_per_angle(per_angle_seen)


def print_per_angle(rows) -> None:
    """The mean error of each angle (which of them better labels would mend)."""
    print("\n| clip | labels | " + " | ".join(n.replace("_", " ") for n in ANGLE_NAMES) + " |")
    print("|---|---|" + "---:|" * len(ANGLE_NAMES))
    for name, kind, errors in rows:
        print(f"| {name} | {kind} | " + " | ".join(f"{e:.2f}" for e in errors) + " |")


if __name__ == "__main__":
    main()
