"""What a pose method returns for one frame."""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Protocol

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.skeleton import JOINT_NAMES, angles_dict, joint_angles


class FrameStatus(enum.StrEnum):
    """How a frame was processed."""

    TRACKED = "tracked"
    """Registered from the previous frame."""
    REINITIALIZED = "reinitialized"
    """Labelled afresh (first frame, or after the track was lost)."""
    LOST = "lost"
    """A person may be there but no pose could be recovered (or the frame was unreadable)."""
    NO_PERSON = "no_person"
    """No person was found in the frame."""


def _frozen(array: np.ndarray | None, dtype: type = np.float64) -> np.ndarray:
    out = np.array(array, dtype=dtype, copy=True)
    out.setflags(write=False)
    return out


@dataclass(frozen=True)
class FrameResult:
    """One frame's recovered pose.

    Parameters
    ----------
    index : int
        The frame's index in its sequence.
    status : FrameStatus
    joints : (15, 3) float
        Joint positions in metres, camera frame (``posedrift.camera``), NaN where
        unknown, in :data:`posedrift.skeleton.JOINT_NAMES` order.
    confidence : (15,) float
        Per-joint confidence in [0, 1]; 0 where unknown.
    points : (N, 3) float
        The frame's (downsampled) person points, camera frame, metres.
    labels : (N,) int
        The part index of each point (:data:`posedrift.skeleton.PART_NAMES`).
    timestamp : float or None
        Seconds, where the source gives one.
    timings_ms : mapping of str to float
        Wall time of each stage, in milliseconds.
    message : str
        Why a frame was lost or had no person, or a read error.
    """

    index: int
    status: FrameStatus
    joints: np.ndarray
    confidence: np.ndarray
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    timestamp: float | None = None
    timings_ms: Mapping[str, float] = field(default_factory=dict)
    message: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", FrameStatus(self.status))
        joints = _frozen(self.joints)
        if joints.shape != (len(JOINT_NAMES), 3):
            raise ValueError(f"FrameResult 'joints' must have shape (15, 3). Got {joints.shape}.")
        confidence = _frozen(self.confidence)
        if confidence.shape != (len(JOINT_NAMES),):
            raise ValueError(
                f"FrameResult 'confidence' must have shape (15,). Got {confidence.shape}."
            )
        object.__setattr__(self, "joints", joints)
        object.__setattr__(self, "confidence", confidence)
        object.__setattr__(self, "points", _frozen(self.points).reshape(-1, 3))
        object.__setattr__(self, "labels", _frozen(self.labels, np.int64).reshape(-1))
        object.__setattr__(self, "timings_ms", MappingProxyType(dict(self.timings_ms)))

    @classmethod
    def empty(
        cls,
        index: int,
        status: FrameStatus,
        message: str = "",
        *,
        timestamp: float | None = None,
        timings_ms: Mapping[str, float] | None = None,
    ) -> FrameResult:
        """A frame with no pose (``lost`` or ``no_person``)."""
        return cls(
            index=index,
            status=status,
            joints=np.full((len(JOINT_NAMES), 3), np.nan),
            confidence=np.zeros(len(JOINT_NAMES)),
            timestamp=timestamp,
            timings_ms=timings_ms or {},
            message=message,
        )

    @property
    def angles(self) -> np.ndarray:
        """The eight angles of Table 1 in degrees (``ANGLE_NAMES`` order), NaN where unknown."""
        return joint_angles(self.joints)

    @property
    def has_pose(self) -> bool:
        """Whether the joints are known."""
        return bool(np.isfinite(self.joints).all())

    def to_json(self) -> dict:
        """The frame object of ``poses.json`` (``METHOD.md`` section 6)."""
        joints = [None if not np.isfinite(j).all() else [float(v) for v in j] for j in self.joints]
        out = {
            "index": int(self.index),
            "status": self.status.value,
            "joints": joints,
            "confidence": [float(c) for c in self.confidence],
            "angles_deg": angles_dict(self.angles),
        }
        if self.timestamp is not None:
            out["timestamp"] = float(self.timestamp)
        if self.message:
            out["message"] = self.message
        return out


class PoseMethod(Protocol):
    """A pose-recovery method: the tracker and every baseline.

    It is built for one camera and then given depth frames, in order, one at a
    time. Depth frames and intrinsics are all it ever receives.
    """

    name: str

    def reset(self, intrinsics: Intrinsics) -> None:
        """Forget any track and prepare for a new sequence from this camera."""

    def process(self, frame: DepthFrame) -> FrameResult:
        """Recover the pose in one frame."""
