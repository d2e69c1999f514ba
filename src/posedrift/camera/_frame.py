"""The depth frame: what a method is allowed to see."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from posedrift.camera._intrinsics import Intrinsics

MAX_PERSON_DEPTH = 20.0
"""Metres. No depth camera sees a person further away: larger depths are raw sensor
units (millimetres, say) read as metres."""


@dataclass(frozen=True)
class DepthFrame:
    """One depth image with its camera: the only input a pose method receives.

    It carries no ground truth by construction; evaluation data travels in
    separate types that methods never receive.

    Parameters
    ----------
    depth : (H, W) float32
        Depth in metres along the optical axis; 0 where there is no measurement.
    intrinsics : Intrinsics
    index : int
        Frame number in its sequence.
    timestamp : float or None
        Seconds since the sequence started, where the source gives one.
    source : str
        Where the frame came from (a file name, ``"synthetic"``), for messages.
    """

    depth: np.ndarray
    intrinsics: Intrinsics
    index: int = 0
    timestamp: float | None = None
    source: str = ""

    def __post_init__(self) -> None:
        depth = np.asarray(self.depth)
        where = f" (frame {self.index}{', ' + self.source if self.source else ''})"
        if depth.ndim != 2 or depth.shape != self.intrinsics.shape:
            raise ValueError(
                f"A depth frame{where} must be a 2-D image of shape {self.intrinsics.shape} "
                f"(height, width) to match its intrinsics. Got shape {depth.shape}."
            )
        if not np.issubdtype(depth.dtype, np.number) or np.issubdtype(
            depth.dtype, np.complexfloating
        ):
            raise ValueError(
                f"A depth frame{where} must hold real numbers. Got dtype {depth.dtype}."
            )
        depth = depth.astype(np.float32, copy=True)
        depth[~np.isfinite(depth) | (depth < 0)] = 0.0
        depth.setflags(write=False)
        object.__setattr__(self, "depth", depth)

    @classmethod
    def from_raw(
        cls,
        raw: np.ndarray,
        intrinsics: Intrinsics,
        *,
        depth_scale: float = 1000.0,
        index: int = 0,
        timestamp: float | None = None,
        source: str = "",
    ) -> DepthFrame:
        """From sensor units (``depth_scale`` units per metre: 1000 for millimetres)."""
        if not depth_scale > 0:
            raise ValueError(
                f"The 'depth_scale' must be positive units per metre. Got {depth_scale!r}."
            )
        raw = np.asarray(raw)
        if not np.issubdtype(raw.dtype, np.number):
            raise ValueError(
                f"A depth frame (frame {index}{', ' + source if source else ''}) must hold "
                f"numbers. Got dtype {raw.dtype}."
            )
        return cls(
            depth=raw.astype(np.float32) / np.float32(depth_scale),
            intrinsics=intrinsics,
            index=index,
            timestamp=timestamp,
            source=source,
        )
