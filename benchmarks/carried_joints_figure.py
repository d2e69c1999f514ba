"""How the tracker carries the previous skeleton into a new frame, against the truth.

Each frame the tracker predicts the previous frame's joints in the new one. Nonrigid
CPD's displacement field is fitted on the template's surface points, and the joints
lie inside the body: this script measures, on a rendered clip, how far each joint's
predicted motion is from its true motion (the ground truth's joint from one frame to
the next), binned by the joint's distance from the template's nearest point, for

- the field evaluated at the joint (the prediction before the carried joints);
- the carried joints (``_carry_joints``: the field near the template, the body's
  rigid motion away from it; what the tracker uses);
- the motion of the template's points near the joint (for scale).

It reads ground truth, so it lives here, beside the method, never in it. Prints a
table and writes a figure.

Usage (about 20 s for 300 frames)::

    OMP_NUM_THREADS=1 python benchmarks/carried_joints_figure.py \\
        ../shared/data/mocap/cmu/002_07.bvh docs/images/carried_joints.png --frames 300
"""

from __future__ import annotations

import argparse
import itertools

import numpy as np
from scipy.spatial.distance import cdist

from posedrift.synthetic import build_sequence, bvh_motion, procedural_motion
from posedrift.tracking import PoseTracker
from posedrift.tracking._tracker import _carry_joints

BINS_CM = (0.0, 3.0, 5.0, 8.0, 15.0, np.inf)
NEIGHBOURHOOD = 0.03  # metres: the template's points "near" a joint (Gaussian width)


class RecordingTracker(PoseTracker):
    """A tracker that records, per tracked frame, its previous joints and registration."""

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.records: list[dict] = []
        self.frame_index = -1

    def _register(self, source, target, labels, correspondence):
        out = super()._register(source, target, labels, correspondence)
        res = out[2]
        if res is not None:
            self.records.append(
                {
                    "frame": self.frame_index,
                    "joints": self._state.joints,
                    "source": source,
                    "moved": res.moved,
                    "field": res.apply,
                }
            )
        return out


def measure(sequence) -> dict[str, np.ndarray]:
    """Per joint and tracked frame: distance to the template and the three motions' errors."""
    tracker = RecordingTracker(sequence.frames[0].intrinsics)
    for t, frame in enumerate(sequence.frames):
        tracker.frame_index = t
        tracker.process(frame)
    truth = np.asarray(sequence.reference.joints)
    out = {k: [] for k in ("gap", "field", "carried", "local", "true")}
    for rec in tracker.records:
        t, joints, source, moved = rec["frame"], rec["joints"], rec["source"], rec["moved"]
        true_step = truth[t] - truth[t - 1]
        d2 = cdist(joints, source, "sqeuclidean")
        weights = np.exp(-(d2 - d2.min(axis=1, keepdims=True)) / (2 * NEIGHBOURHOOD**2))
        local = weights @ (moved - source) / weights.sum(axis=1, keepdims=True)
        steps = {
            "field": rec["field"](joints) - joints,
            "carried": _carry_joints(joints, source, moved, rec["field"]) - joints,
            "local": local,
        }
        out["gap"].append(np.sqrt(d2.min(axis=1)))
        out["true"].append(np.linalg.norm(true_step, axis=1))
        for name, step in steps.items():
            out[name].append(np.linalg.norm(step - true_step, axis=1))
    return {k: 100.0 * np.concatenate(v) for k, v in out.items()}  # centimetres


def table(m: dict[str, np.ndarray]) -> list[tuple]:
    rows = []
    for lo, hi in itertools.pairwise(BINS_CM):
        inside = (m["gap"] >= lo) & (m["gap"] < hi)
        if inside.any():
            medians = (
                float(np.median(m[k][inside])) for k in ("true", "field", "carried", "local")
            )
            rows.append((lo, hi, int(inside.sum()), *medians))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("clip", help="a BVH file, or 'builtin'")
    parser.add_argument("out", help="the PNG to write")
    parser.add_argument("--frames", type=int, default=300)
    parser.add_argument("--distance", type=float, default=None, help="metres from the camera")
    args = parser.parse_args()
    motion = procedural_motion() if args.clip == "builtin" else bvh_motion(args.clip)
    place = {} if args.distance is None else {"distance": args.distance}
    sequence = build_sequence(motion, n_frames=args.frames, in_place=True, rng=0, **place)
    rows = table(measure(sequence))

    print(
        "| distance to the template (cm) | joints | true motion (= no motion's error) | field's "
        "error | carried joints' error | nearby points' error |"
    )
    print("|---|---:|---:|---:|---:|---:|")
    for lo, hi, n, true, field, carried, local in rows:
        print(f"| {lo:g}-{hi:g} | {n} | {true:.2f} | {field:.2f} | {carried:.2f} | {local:.2f} |")

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [f"{lo:g}-{hi:g}" for lo, hi, *_ in rows]
    x = np.arange(len(rows))
    fig, ax = plt.subplots(figsize=(7, 4))
    for k, (name, colour) in enumerate(
        (
            ("the field at the joint", "tab:red"),
            ("carried joints (shipped)", "tab:blue"),
            ("the nearby template points' motion", "tab:grey"),
        )
    ):
        ax.bar(x + (k - 1) * 0.27, [r[4 + k] for r in rows], 0.27, label=name, color=colour)
    ax.plot(x, [r[3] for r in rows], "k.--", label="no motion predicted (the true motion)")
    ax.set_xticks(x, labels)
    ax.set_xlabel("joint's distance from the template's nearest point (cm)")
    ax.set_ylabel("median error of the predicted motion (cm)")
    ax.set_title(f"{args.clip.split('/')[-1]}: the previous joints carried into the next frame")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(args.out, dpi=110)
    print(f"figure: {args.out}")


if __name__ == "__main__":
    main()
