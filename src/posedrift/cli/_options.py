"""Command-line options shared by the commands that read a depth recording."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from posedrift.camera import CAMERA_PRESETS

DepthInput = Annotated[
    Path,
    typer.Argument(
        help="Depth input: a folder of 16-bit PNGs, .npy/.npz stack, UTD-MHAD .mat, "
        "RealSense .bag/.db3."
    ),
]
CameraOption = Annotated[
    str | None,
    typer.Option("--camera", help=f"Camera preset: {', '.join(CAMERA_PRESETS)}."),
]
IntrinsicsOption = Annotated[
    str | None, typer.Option("--intrinsics", help="fx,fy,cx,cy in pixels.")
]
DepthScaleOption = Annotated[
    str | None,
    typer.Option(
        "--depth-scale",
        help="Depth units per metre: 1000 (mm, default), 5000 (TUM), or mm / tum / m.",
    ),
]
FpsOption = Annotated[
    float, typer.Option("--fps", min=0.001, help="Frame rate where the input has none.")
]
UnmirrorOption = Annotated[
    bool | None,
    typer.Option(
        "--unmirror/--no-unmirror",
        help="Flip mirrored recordings left-right (default: only UTD-MHAD .mat files).",
    ),
]


def depth_scale_hint(depth_m: float) -> str:
    """A hint where depths (metres, as read) are too far for a person, else ""."""
    from posedrift.camera._frame import MAX_PERSON_DEPTH

    if not (np.isfinite(depth_m) and depth_m > MAX_PERSON_DEPTH):
        return ""
    return (
        f"depths of {depth_m:g} m look like raw sensor units read as metres: "
        f"give --depth-scale (1000 for millimetres)"
    )
