"""The pictures and files that ``track`` and ``demo`` leave in their output folder.

Also the up-front checks of output paths that every command writing files runs
before any work: :func:`check_output_dir` and :func:`check_output_file`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Sequence
from pathlib import Path

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.tracking import FrameResult

logger = logging.getLogger("posedrift.cli")

MAX_VIDEO_FRAMES = 300
"""Longer sequences are strided so the animation stays a few megabytes."""


def _output_problem(path: Path) -> str | None:
    """Why nothing could be written under ``path``'s parent, or None when it can.

    Walks up to the nearest existing ancestor: it must be a writable folder
    (a file on the way, e.g. ``afile/x.gif`` with ``afile`` a file, is an error).
    """
    parent = path.parent
    while not parent.exists() and parent != parent.parent:
        parent = parent.parent
    if not parent.is_dir():
        return f"{str(parent)!r} is a file, not a folder"
    if not os.access(parent, os.W_OK | os.X_OK):
        return f"the folder {str(parent)!r} is not writable"
    return None


def check_output_dir(path: str | Path, option: str) -> Path:
    """Fail now, with a usage error, if ``path`` cannot become an output folder.

    Call it before any work so that a bad ``--out`` costs nothing. The folder
    itself is not created.

    Parameters
    ----------
    path : str or Path
        The output folder asked for (it may exist or not).
    option : str
        The option that gave it, e.g. ``"--out"``, named in the message.

    Returns
    -------
    Path
        ``path`` as a Path.

    Raises
    ------
    typer.Exit
        With code 2 after printing ``error: <option> ...`` naming the path, when
        ``path`` is an existing file, lies under a file, or under a folder that is
        not writable.

    Examples
    --------
    >>> str(check_output_dir("results/run1", "--out"))
    'results/run1'
    """
    from posedrift.cli._app import fail

    path = Path(path)
    if path.exists():
        if not path.is_dir():
            raise fail(f"{option} {str(path)!r} is an existing file, not a folder.")
        if not os.access(path, os.W_OK | os.X_OK):
            raise fail(f"{option} {str(path)!r}: the folder is not writable.")
        return path
    problem = _output_problem(path)
    if problem:
        raise fail(f"{option} {str(path)!r} cannot be created: {problem}.")
    return path


def check_output_file(
    path: str | Path, option: str, *, suffixes: Sequence[str] | None = None
) -> Path:
    """Fail now, with a usage error, if ``path`` cannot be written as a file.

    Parameters
    ----------
    path : str or Path
        The output file asked for; an existing file is overwritten.
    option : str
        The option that gave it, e.g. ``"--out"``, named in the message.
    suffixes : sequence of str, optional
        The extensions accepted (``(".gif", ".mp4")``), compared case-insensitively.

    Returns
    -------
    Path
        ``path`` as a Path.

    Raises
    ------
    typer.Exit
        With code 2 after printing ``error: <option> ...`` naming the path, when the
        extension is not one of ``suffixes``, ``path`` is a folder, lies under a
        file, or under a folder that is not writable.

    Examples
    --------
    >>> str(check_output_file("preview.gif", "--out", suffixes=(".gif", ".mp4")))
    'preview.gif'
    """
    from posedrift.cli._app import fail

    path = Path(path)
    if suffixes is not None and path.suffix.lower() not in {s.lower() for s in suffixes}:
        raise fail(
            f"{option} {str(path)!r} must end in {' or '.join(suffixes)}. "
            f"Got {path.suffix or 'no extension'!r}."
        )
    if path.is_dir():
        raise fail(f"{option} {str(path)!r} is a folder, not a file.")
    if path.exists() and not os.access(path, os.W_OK):
        raise fail(f"{option} {str(path)!r}: the file is not writable.")
    problem = _output_problem(path)
    if problem:
        raise fail(f"{option} {str(path)!r} cannot be written: {problem}.")
    return path


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
    smoothing: dict | None = None,
) -> dict[str, Path]:
    """Write poses (JSON, CSV, BVH), the animation, the viewer and the angle plot.

    The poses are written first, so a failure in a picture loses no result; a
    picture that cannot be made is logged and skipped. The animation shows every
    ``stride``-th frame (default :func:`video_stride` of the sequence's length).
    """
    from posedrift.io import write_poses

    out.mkdir(parents=True, exist_ok=True)
    written = dict(
        write_poses(
            results,
            out,
            intrinsics=intrinsics,
            fps=fps,
            joint_convention=joint_convention,
            smoothing=smoothing,
        )
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
