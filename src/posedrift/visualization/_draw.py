"""Pictures of one frame (depth, labels, points, skeleton) and the side-by-side video."""

from __future__ import annotations

import importlib.util
import logging
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics, project
from posedrift.skeleton import JOINT_PARENTS, PART_COLOURS, PART_NAMES
from posedrift.tracking import FrameResult

logger = logging.getLogger("posedrift.visualization")

BACKGROUND = (0, 0, 0)
SKELETON_COLOUR = (255, 255, 255)
JOINT_COLOUR = (255, 210, 0)
LABEL_LUT = np.array((BACKGROUND, *PART_COLOURS), dtype=np.uint8)
"""Label image value (part index + 1, 0 background) -> RGB."""


def draw_label_image(labels: np.ndarray, *, zero_based: bool = False) -> np.ndarray:
    """Colour a part-label image with :data:`posedrift.skeleton.PART_COLOURS`.

    Parameters
    ----------
    labels : (H, W) int
        ``part index + 1`` with 0 for background (the product's label images), or,
        with ``zero_based=True``, the part index with -1 for background (the
        forest's predictions).
    zero_based : bool

    Returns
    -------
    (H, W, 3) uint8
        Black background; values outside the parts are drawn grey.

    Examples
    --------
    >>> import numpy as np
    >>> draw_label_image(np.array([[0, 1, 15]]))[0].tolist()
    [[0, 0, 0], [230, 25, 75], [0, 0, 128]]
    """
    labels = np.asarray(labels)
    if labels.ndim != 2 or not np.issubdtype(labels.dtype, np.integer):
        raise ValueError(
            f"The 'labels' of draw_label_image must be a 2-D integer image. "
            f"Got shape {labels.shape}, dtype {labels.dtype}."
        )
    index = labels.astype(np.int64) + (1 if zero_based else 0)
    lut = np.vstack([LABEL_LUT, [[128, 128, 128]]]).astype(np.uint8)
    index = np.where((index >= 0) & (index <= len(PART_NAMES)), index, len(lut) - 1)
    return lut[index]


def depth_image(depth: np.ndarray, *, near: float | None = None, far: float | None = None):
    """A greyscale ``(H, W, 3)`` uint8 picture of depth in metres: near bright, none black."""
    depth = np.asarray(depth, dtype=float)
    valid = np.isfinite(depth) & (depth > 0)
    out = np.zeros((*depth.shape, 3), dtype=np.uint8)
    if not valid.any():
        return out
    lo = np.percentile(depth[valid], 1) if near is None else near
    hi = np.percentile(depth[valid], 99) if far is None else far
    span = max(hi - lo, 1e-6)
    grey = 255 - 200 * np.clip((depth - lo) / span, 0, 1)
    out[valid] = grey[valid, None].astype(np.uint8)
    return out


def draw_points_image(
    points: np.ndarray,
    labels: np.ndarray,
    intrinsics: Intrinsics,
    *,
    radius: int = 1,
) -> np.ndarray:
    """Labelled 3-D points projected into the camera image, far points drawn first.

    Parameters
    ----------
    points : (N, 3) float
        Camera frame, metres.
    labels : (N,) int
        Part index (0..14); other values are drawn grey.
    intrinsics : Intrinsics
    radius : int
        Half-size in pixels of each drawn point.

    Returns
    -------
    (H, W, 3) uint8
    """
    image = np.zeros((*intrinsics.shape, 3), dtype=np.uint8)
    points = np.asarray(points, dtype=float).reshape(-1, 3)
    labels = np.asarray(labels).reshape(-1)
    if len(points) == 0:
        return image
    if len(labels) != len(points):
        labels = np.full(len(points), -1)
    keep = np.isfinite(points).all(axis=1) & (points[:, 2] > 0)
    points, labels = points[keep], labels[keep]
    order = np.argsort(-points[:, 2])
    uv = np.rint(project(points[order], intrinsics)).astype(int)
    colours = draw_label_image(labels[order][None, :], zero_based=True)[0]
    for dy in range(-radius, radius + 1):
        for dx in range(-radius, radius + 1):
            u, v = uv[:, 0] + dx, uv[:, 1] + dy
            inside = (u >= 0) & (u < intrinsics.width) & (v >= 0) & (v < intrinsics.height)
            image[v[inside], u[inside]] = colours[inside]
    return image


def draw_skeleton(
    image: np.ndarray,
    joints: np.ndarray,
    intrinsics: Intrinsics,
    *,
    colour: tuple[int, int, int] = SKELETON_COLOUR,
    width: int = 2,
) -> np.ndarray:
    """Draw the 15-joint skeleton (camera frame, metres) onto a copy of an RGB image.

    Bones follow :data:`posedrift.skeleton.JOINT_PARENTS`; unknown (NaN) joints
    and their bones are left out. Joints are yellow dots.
    """
    from PIL import Image, ImageDraw

    picture = Image.fromarray(np.ascontiguousarray(image, dtype=np.uint8))
    pen = ImageDraw.Draw(picture)
    joints = np.asarray(joints, dtype=float).reshape(-1, 3)
    known = np.isfinite(joints).all(axis=1) & (joints[:, 2] > 0)
    uv = np.full((len(joints), 2), np.nan)
    if known.any():
        uv[known] = project(joints[known], intrinsics)
    for j, p in enumerate(JOINT_PARENTS):
        if p >= 0 and known[j] and known[p]:
            pen.line([tuple(uv[p]), tuple(uv[j])], fill=colour, width=width)
    dot = width + 1
    for j in np.flatnonzero(known):
        u, v = uv[j]
        pen.ellipse([u - dot, v - dot, u + dot, v + dot], fill=JOINT_COLOUR)
    return np.asarray(picture)


def _caption(image: np.ndarray, text: str) -> np.ndarray:
    from PIL import Image, ImageDraw

    picture = Image.fromarray(image)
    ImageDraw.Draw(picture).text((4, 3), text, fill=(255, 255, 0))
    return np.asarray(picture)


def frame_panels(
    frame: DepthFrame | object | None,
    result: FrameResult | None,
    intrinsics: Intrinsics,
    *,
    body: object | None = None,
) -> np.ndarray:
    """One video frame: depth | labelled points | skeleton on depth [| posed body].

    ``frame`` may be an :class:`~posedrift.io.UnreadableFrame` or None (a black
    depth panel with its message). ``body`` is a ``synthetic.BodyModel``.
    """
    height, width = intrinsics.shape
    if isinstance(frame, DepthFrame):
        depth = depth_image(frame.depth)
        note = f"frame {frame.index}"
    else:
        depth = np.zeros((height, width, 3), dtype=np.uint8)
        message = getattr(frame, "message", "no depth")
        note = f"unreadable: {message}"[:60]
    panels = [_caption(depth, note)]
    if result is None:
        points = np.zeros((height, width, 3), dtype=np.uint8)
        skeleton = (depth * 0.5).astype(np.uint8)
        status = ""
    else:
        points = draw_points_image(result.points, result.labels, intrinsics)
        skeleton = draw_skeleton((depth * 0.5).astype(np.uint8), result.joints, intrinsics)
        status = result.status.value
    panels.append(_caption(points, f"labels {len(result.points) if result else 0} pts"))
    panels.append(_caption(skeleton, status))
    if body is not None:
        from posedrift.visualization._body import render_posed_body

        if result is not None and result.has_pose:
            shown = render_posed_body(result.joints, intrinsics, body=body)
        else:
            shown = np.zeros((height, width, 3), dtype=np.uint8)
        panels.append(_caption(shown, "body"))
    gap = np.full((height, 2, 3), 64, dtype=np.uint8)
    row = [panels[0]]
    for panel in panels[1:]:
        row += [gap, panel]
    return np.concatenate(row, axis=1)


def write_video(
    frames: Sequence[DepthFrame | object | None],
    results: Sequence[FrameResult],
    path: str | Path,
    *,
    fps: float = 15.0,
    body: object | None = None,
    intrinsics: Intrinsics | None = None,
    progress: bool = False,
) -> Path:
    """Write an animation of depth, labelled points and skeleton side by side.

    Parameters
    ----------
    frames : sequence of DepthFrame (or UnreadableFrame / None)
        The input frames, aligned with ``results`` (same length and order).
    results : sequence of FrameResult
    path : str or Path
        ``.gif`` (always available: Pillow) or ``.mp4`` (needs ``imageio-ffmpeg``).
    fps : float
        Playback rate.
    body : synthetic.BodyModel, optional
        Adds a fourth panel: the body model posed on the recovered joints and rendered.
    intrinsics : Intrinsics, optional
        Needed only when no frame is a DepthFrame.
    progress : bool
        Show a progress bar (rich) while drawing.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        If the lengths differ, the suffix is not supported, MP4 is asked for
        without ``imageio-ffmpeg``, or no intrinsics can be found.
    """
    path = Path(path)
    frames, results = list(frames), list(results)
    if len(frames) != len(results):
        raise ValueError(
            f"write_video needs one result per frame. Got {len(frames)} frames and "
            f"{len(results)} results."
        )
    _check_animation_path(path, fps, "write_video")
    if intrinsics is None:
        intrinsics = next((f.intrinsics for f in frames if isinstance(f, DepthFrame)), None)
    if intrinsics is None:
        raise ValueError("write_video needs 'intrinsics' when no frame is a DepthFrame.")
    if not frames:
        raise ValueError("write_video got no frames.")
    pictures = []
    for frame, result in _progress(zip(frames, results, strict=True), len(frames), progress):
        pictures.append(frame_panels(frame, result, intrinsics, body=body))
    return _write_animation(pictures, path, fps)


def _check_animation_path(path: Path, fps: float, caller: str) -> None:
    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ValueError(f"{caller} writes .gif or .mp4. Got {str(path)!r}.")
    if suffix == ".mp4" and importlib.util.find_spec("imageio_ffmpeg") is None:
        raise ValueError(
            f"Writing {path.name} needs imageio-ffmpeg (pip install imageio-ffmpeg); "
            f"or write a .gif instead."
        )
    if not (np.isfinite(fps) and fps > 0):
        raise ValueError(f"The 'fps' of {caller} must be positive. Got {fps!r} instead.")


def _write_animation(pictures: list[np.ndarray], path: Path, fps: float) -> Path:
    import imageio.v3 as iio

    path.parent.mkdir(parents=True, exist_ok=True)
    stack = np.stack(pictures)
    if path.suffix.lower() == ".gif":
        iio.imwrite(path, stack, plugin="pillow", duration=1000.0 / fps, loop=0)
    else:
        # pad to whole 16-pixel macro blocks so that the encoder does not resize
        pad_h, pad_w = (-stack.shape[1]) % 16, (-stack.shape[2]) % 16
        padded = np.pad(stack, ((0, 0), (0, pad_h), (0, pad_w), (0, 0)))
        _encode_mp4(padded, path, fps)
    return path


def _encode_mp4(stack: np.ndarray, path: Path, fps: float) -> None:
    """H.264 through the ffmpeg binary that imageio-ffmpeg ships (one process, no leaks)."""
    import subprocess

    import imageio_ffmpeg

    _, height, width, _ = stack.shape
    command = [
        imageio_ffmpeg.get_ffmpeg_exe(),
        "-y",
        "-loglevel",
        "error",
        "-f",
        "rawvideo",
        "-pix_fmt",
        "rgb24",
        "-s",
        f"{width}x{height}",
        "-r",
        f"{fps:g}",
        "-i",
        "-",
        "-an",
        "-vcodec",
        "libx264",
        "-pix_fmt",
        "yuv420p",
        str(path),
    ]
    run = subprocess.run(
        command, input=np.ascontiguousarray(stack).tobytes(), capture_output=True, check=False
    )
    if run.returncode != 0:
        raise ValueError(
            f"ffmpeg could not write {path}: {run.stderr.decode(errors='replace')[-500:]}"
        )


def write_depth_video(
    frames: Sequence[DepthFrame | object | None],
    path: str | Path,
    *,
    intrinsics: Intrinsics,
    fps: float = 15.0,
) -> Path:
    """Write the depth frames alone as an animation (a preview of an input).

    Unreadable frames (or None) are black with their message.
    """
    path = Path(path)
    _check_animation_path(path, fps, "write_depth_video")
    frames = list(frames)
    if not frames:
        raise ValueError("write_depth_video got no frames.")
    pictures = []
    for i, frame in enumerate(frames):
        if isinstance(frame, DepthFrame):
            pictures.append(_caption(depth_image(frame.depth), f"frame {frame.index}"))
        else:
            blank = np.zeros((*intrinsics.shape, 3), dtype=np.uint8)
            message = getattr(frame, "message", "no depth")
            pictures.append(_caption(blank, f"frame {i} unreadable: {message}"[:60]))
    return _write_animation(pictures, path, fps)


def _progress(iterable, total: int, enabled: bool):
    if not enabled:
        yield from iterable
        return
    from rich.progress import track

    yield from track(iterable, total=total, description="Drawing video", transient=True)
