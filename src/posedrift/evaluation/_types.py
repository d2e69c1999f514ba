"""Evaluation data: what the evaluator sees and methods never do."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedrift.camera import DepthFrame
from posedrift.skeleton import ANGLE_NAMES, JOINT_NAMES


@dataclass(frozen=True)
class Reference:
    """Ground truth (synthetic) or a reference skeleton (e.g. Kinect) for a sequence.

    Parameters
    ----------
    joints : (T, 15, 3) float
        Metres, camera frame, NaN where unknown.
    angles : (T, 8) float
        Degrees, in ``ANGLE_NAMES`` order.
    labels : tuple of (H, W) uint8, or None
        Per-pixel part labels (part index + 1, 0 background), where known.
    kind : str
        ``"synthetic"`` (exact) or ``"kinect"`` (an estimate used as reference).
    """

    joints: np.ndarray
    angles: np.ndarray
    labels: tuple[np.ndarray, ...] | None = None
    kind: str = "synthetic"

    def __post_init__(self) -> None:
        joints = np.asarray(self.joints, dtype=float)
        angles = np.asarray(self.angles, dtype=float)
        if joints.ndim != 3 or joints.shape[1:] != (len(JOINT_NAMES), 3):
            raise ValueError(f"Reference 'joints' must be (T, 15, 3). Got {joints.shape}.")
        if angles.shape != (len(joints), len(ANGLE_NAMES)):
            raise ValueError(
                f"Reference 'angles' must be (T, 8) with T = {len(joints)}. Got {angles.shape}."
            )
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "angles", angles)

    def __len__(self) -> int:
        return len(self.joints)


@dataclass(frozen=True)
class EvaluationSequence:
    """Depth frames for the methods and a reference for the evaluator, kept apart.

    The harness hands ``frames`` to methods and ``reference`` to the metrics only.
    """

    name: str
    frames: tuple[DepthFrame, ...]
    reference: Reference
    fps: float = 30.0

    def __post_init__(self) -> None:
        if len(self.frames) != len(self.reference):
            raise ValueError(
                f"Sequence {self.name!r} has {len(self.frames)} depth frames but a reference "
                f"of {len(self.reference)} frames."
            )
