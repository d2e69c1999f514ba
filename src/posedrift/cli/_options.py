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
        help="Body-part net file that labels the trackers' pixels (default: the shipped "
        "frontal, turned, high and back nets); 'none' leaves the labels to the forest.",
    ),
]
TurnedNetOption = Annotated[
    str | None,
    typer.Option(
        "--turned-net",
        help="Body-part net file that takes over once the skeleton turns away (default: "
        "the shipped one, unless --net names a file); 'none': the --net net for every view.",
    ),
]
CameraTiltOption = Annotated[
    float,
    typer.Option(
        "--camera-tilt",
        help="Degrees the camera looks down, in (-90, 90) (negative: up; 0: level, the "
        "protocol's).",
    ),
]
FpsOption = Annotated[
    float, typer.Option("--fps", min=0.001, help="Frame rate where the input has none.")
]
SmoothOption = Annotated[
    float,
    typer.Option(
        "--smooth",
        min=0.0,
        help="Smooth the joints offline over the whole recording, without lag: a local "
        "quadratic in time with Gaussian weights of this many seconds (0.1 is a good start; "
        "0, the default, keeps each frame's joints as tracked).",
    ),
]
SmoothLagOption = Annotated[
    float | None,
    typer.Option(
        "--smooth-lag",
        min=0.0,
        help="With --smooth: use only the frames up to this many seconds after each one "
        "(what a live stream smoothed with that latency gets, posedrift.tracking.LiveSmoother; "
        "default: the whole window).",
    ),
]


def check_smoothing(smooth: float, smooth_lag: float | None) -> None:
    """Fail (exit 2) for --smooth-lag without --smooth."""
    if smooth_lag is not None and not smooth:
        raise fail("--smooth-lag needs --smooth (the smoothing's width, seconds).")


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


def load_part_net(net: str | None, turned_net: str | None = None):
    """``--net`` and ``--turned-net``: what labels the trackers' pixels.

    None (both unset: the shipped pair, loaded where used), "none" (the forest), a
    net read from the file named, or a :class:`~posedrift.labelling.FacingNets`
    pair of it and the turned net.

    Raises
    ------
    typer.Exit
        Exit status 2, with the reader's message, if a file is not a body-part net,
        or if --turned-net is given with --net none.
    """
    if net == "none":
        if turned_net not in (None, "none"):
            raise fail("--turned-net needs a part net: it cannot be used with --net none.")
        return net
    if net is None and turned_net is None:
        return None
    from posedrift.labelling import BodyPartNet, FacingNets

    def read(path: str) -> BodyPartNet:
        try:
            return BodyPartNet.load(path)
        except ValueError as exc:
            raise fail(str(exc)) from exc

    frontal = BodyPartNet.load_default() if net is None else read(net)
    if turned_net == "none" or (turned_net is None and net is not None):
        return frontal
    turned = BodyPartNet.load_default("turned") if turned_net is None else read(turned_net)
    return FacingNets(frontal, turned)
