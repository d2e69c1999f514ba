"""Fit the Kinect joint convention (``posedrift.skeleton.CONVENTIONS["kinect"]``).

Usage::

    python scripts/fit_kinect_convention.py ../shared/data/utd-mhad
    python scripts/fit_kinect_convention.py ROOT --subjects 1,2,3,4 --trials 1

Runs the default :class:`~posedrift.tracking.PoseTracker` over UTD-MHAD recordings
(depth and intrinsics only), then fits, per joint, the median offset from the
recovered joint to the Kinect SDK's in the recovered skeleton's body frame
(:func:`posedrift.skeleton.fit_convention`). Prints:

- a two-fold cross-validation by subject (fit on half the subjects, score the other
  half): MPJPE and mAP@10cm before and after the conversion, so that the offsets are
  seen to carry over to people they were not fitted on;
- the offsets fitted on all the given sequences, as Python source for
  ``src/posedrift/skeleton/_convention.py``.

Refit whenever the tracker's skeleton changes. About 75 s for 108 sequences (one core).
"""

from __future__ import annotations

import argparse

import numpy as np

from posedrift.evaluation import find_utd_sequences, load_utd_sequence, map_at, mpjpe_mm
from posedrift.skeleton import JOINT_NAMES, fit_convention
from posedrift.skeleton._convention import body_frame
from posedrift.tracking import PoseTracker


def _apply(joints: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    axes, trunk = body_frame(joints)
    return joints + np.einsum("...ab,ja->...jb", axes, offsets) * trunk[..., None, None]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("root", help="UTD-MHAD folder holding Depth/ and Skeleton/")
    parser.add_argument("--subjects", default="1,2,3,4")
    parser.add_argument("--trials", default="1")
    args = parser.parse_args()
    subjects = [int(s) for s in args.subjects.split(",")]
    trials = {int(t) for t in args.trials.split(",")}
    found, _ = find_utd_sequences(args.root)
    runs: dict[int, list[tuple[np.ndarray, np.ndarray]]] = {s: [] for s in subjects}
    for name, depth_path, skeleton_path in found:
        subject = int(name.split("_s")[1].split("_")[0])
        trial = int(name.split("_t")[1].split("_")[0])
        if subject not in runs or trial not in trials:
            continue
        seq = load_utd_sequence(depth_path, skeleton_path, name=name)
        tracker = PoseTracker(seq.frames[0].intrinsics)
        est = np.stack([tracker.process(frame).joints for frame in seq.frames])
        runs[subject].append((est, seq.reference.joints))
        print(f"{name}: {len(est)} frames", flush=True)

    def stack(group):
        pairs = [p for s in group for p in runs[s]]
        return np.concatenate([p[0] for p in pairs]), np.concatenate([p[1] for p in pairs])

    half = len(subjects) // 2
    folds = [(subjects[:half], subjects[half:]), (subjects[half:], subjects[:half])]
    for fit_on, test_on in folds:
        if not fit_on or not test_on:
            continue
        offsets = fit_convention(*stack(fit_on))
        est, ref = stack(test_on)
        moved = _apply(est, offsets)
        print(
            f"fit on subjects {fit_on}, scored on {test_on}: MPJPE {mpjpe_mm(est, ref):.1f} -> "
            f"{mpjpe_mm(moved, ref):.1f} mm, mAP@10cm {map_at(est, ref):.3f} -> "
            f"{map_at(moved, ref):.3f}"
        )
    offsets = fit_convention(*stack(subjects))
    print("_KINECT_OFFSETS = np.array(\n    [")
    for name, row in zip(JOINT_NAMES, offsets, strict=True):
        print(f"        [{row[0]:.3f}, {row[1]:.3f}, {row[2]:.3f}],  # {name}")
    print("    ]\n)")


if __name__ == "__main__":
    main()
