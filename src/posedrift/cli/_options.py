"""Command-line options shared by the commands that read a depth recording or track."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import numpy as np
import typer

from posedrift.camera import CAMERA_PRESETS
from posedrift.cli._app import fail

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
NetOption = Annotated[
    str | None,
    typer.Option(
        "--net",
        help="Body-part net file that labels the trackers' pixels (default: shipped); 'none' "
        "leaves the labels to the forest.",
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


def load_part_net(net: str | None):
    """``--net``: None (the shipped net), "none", or the net read from the file named.

    Raises
    ------
    typer.Exit
        Exit status 2, with the reader's message, if the file is not a body-part net.
    """
    if net is None or net == "none":
        return net
    from posedrift.labelling import BodyPartNet

    try:
        return BodyPartNet.load(net)
    except ValueError as exc:
        raise fail(str(exc)) from exc
