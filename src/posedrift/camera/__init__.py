"""Camera model: intrinsics, presets, camera poses, depth frames, and Eq. 1."""

from posedrift.camera._frame import DepthFrame
from posedrift.camera._intrinsics import (
    CAMERA_PRESETS,
    CameraPose,
    Intrinsics,
    backproject,
    camera_preset,
    parse_intrinsics,
    project,
)

__all__ = [
    "CAMERA_PRESETS",
    "CameraPose",
    "DepthFrame",
    "Intrinsics",
    "backproject",
    "camera_preset",
    "parse_intrinsics",
    "project",
]
