"""The pictures and files that ``track`` and ``demo`` leave in their output folder."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from pathlib import Path

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.tracking import FrameResult

logger = logging.getLogger("posedrift.cli")

MAX_VIDEO_FRAMES = 300
"""Longer sequences are strided so the animation stays a few megabytes."""


def video_stride(n_frames: int) -> int:
    """Every how many frames one goes into the animation."""
    return max(1, -(-n_frames // MAX_VIDEO_FRAMES))


def write_outputs(
    results: Sequence[FrameResult],
    frames: Sequence[DepthFrame | object | None],
    out: Path,
    *,
    intrinsics: Intrinsics,
    fps: float,
    reference: object | None = None,
    video: bool = True,
    viewer: bool = True,
    plots: bool = True,
    body: bool = True,
    stride: int | None = None,
    joint_convention: str = "native",
) -> dict[str, Path]:
    """Write poses (JSON, CSV, BVH), the animation, the viewer and the angle plot.

    The poses are written first, so a failure in a picture loses no result; a
    picture that cannot be made is logged and skipped. The animation shows every
    ``stride``-th frame (default :func:`video_stride` of the sequence's length).
    """
    from posedrift.io import write_poses

    out.mkdir(parents=True, exist_ok=True)
    written = dict(
        write_poses(results, out, intrinsics=intrinsics, fps=fps, joint_convention=joint_convention)
    )
    stride = stride or video_stride(len(results))
    jobs = []
    if plots:
        jobs.append(("angles", lambda: _plot(results, out / "angles.png", reference, fps)))
    if viewer:
        jobs.append(("viewer", lambda: _viewer(results, out / "viewer.html", fps)))
    if video:
        jobs.append(
            (
                "video",
                lambda: _video(
                    frames[::stride], results[::stride], out / "tracking.gif", fps / stride, body
                ),
            )
        )
    for name, job in jobs:
        try:
            written[name] = job()
        except Exception as exc:  # a picture must not cost the results
            logger.error("could not write the %s: %s", name, exc)
    return written


def _plot(results, path, reference, fps):
    from posedrift.visualization import plot_angles

    return plot_angles(results, path, reference=reference, fps=fps)


def _viewer(results, path, fps):
    from posedrift.visualization import write_viewer

    return write_viewer(results, path, fps=fps)


def _video(frames, results, path, fps, body):
    from posedrift.visualization import write_video

    model = None
    if body:
        from posedrift.synthetic import BodyModel

        model = BodyModel.load_default()
    return write_video(frames, results, path, fps=min(fps, 15.0), body=model)
