"""Intel RealSense recordings (``.bag`` ROS1, ``.db3`` ROS2) through ``pyrealsense2`` playback."""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np

from posedrift.camera import DepthFrame, Intrinsics
from posedrift.io._readers import (
    DEFAULT_FPS,
    DepthSource,
    UnreadableFrame,
    resolve_depth_scale,
    resolve_intrinsics,
)

_WAIT_MS = 2000


def _import_realsense():
    try:
        import pyrealsense2 as rs
    except ImportError as exc:
        raise ImportError(
            "Reading RealSense recordings needs pyrealsense2: pip install 'posedrift[realsense]'."
        ) from exc
    return rs


class RealSenseSource(DepthSource):
    """The depth stream of a RealSense recording, played back frame by frame (not in real time).

    Intrinsics and the depth unit come from the recording unless given;
    timestamps are the recording's, in seconds since its first depth frame.
    """

    def __init__(
        self,
        path: str | Path,
        *,
        camera: str | None = None,
        intrinsics: Intrinsics | str | Sequence[float] | None = None,
        depth_scale: float | str | None = None,
        fps: float = DEFAULT_FPS,
        unmirror: bool = False,
    ) -> None:
        self.path = Path(path)
        rs = _import_realsense()
        pipeline, profile = self._start(rs)
        try:
            streams = list(profile.get_streams())
            depth = [s for s in streams if s.stream_type() == rs.stream.depth]
            if not depth:
                found = ", ".join(str(s.stream_type()).split(".")[-1] for s in streams) or "none"
                raise ValueError(
                    f"The recording {str(self.path)!r} has no depth stream. Streams found: {found}."
                )
            video = depth[0].as_video_stream_profile()
            own = video.get_intrinsics()
            try:
                units = profile.get_device().first_depth_sensor().get_depth_scale()
            except RuntimeError:
                units = 0.001
        finally:
            pipeline.stop()
        self.fps = float(video.fps() or fps)
        self.depth_scale = resolve_depth_scale(
            depth_scale, default=float(f"{1.0 / float(units):.6g}")
        )
        if camera is None and intrinsics is None:
            self.intrinsics = Intrinsics(
                fx=own.fx, fy=own.fy, cx=own.ppx, cy=own.ppy, width=own.width, height=own.height
            )
        else:
            self.intrinsics = resolve_intrinsics(
                (own.height, own.width), camera=camera, intrinsics=intrinsics, where=str(self.path)
            )
        self._set_unmirror(unmirror)
        self._length: int | None = None

    def _start(self, rs):
        config = rs.config()
        try:
            config.enable_device_from_file(str(self.path), repeat_playback=False)
            config.enable_all_streams()
            pipeline = rs.pipeline()
            profile = pipeline.start(config)
        except RuntimeError as exc:
            raise ValueError(
                f"Cannot play back the RealSense recording {str(self.path)!r}: {exc}"
            ) from exc
        playback = profile.get_device().as_playback()
        playback.set_real_time(False)
        return pipeline, profile

    def _frames(self) -> Iterator[tuple[int, float, np.ndarray | None, str]]:
        """``(index, timestamp_s, raw or None, message)`` for each depth frame."""
        rs = _import_realsense()
        pipeline, profile = self._start(rs)
        playback = profile.get_device().as_playback()
        first = None
        index = 0
        try:
            while True:
                ok, frames = pipeline.try_wait_for_frames(_WAIT_MS)
                if not ok:
                    break
                depth = frames.get_depth_frame()
                if not depth:
                    continue
                stamp_ms = depth.get_timestamp()
                first = stamp_ms if first is None else first
                try:
                    raw = np.array(depth.get_data(), dtype=np.uint16, copy=True)
                    message = ""
                except (RuntimeError, ValueError) as exc:
                    raw, message = None, str(exc)
                yield index, (stamp_ms - first) / 1000.0, raw, message
                index += 1
                if playback.current_status() == rs.playback_status.stopped:
                    break
        finally:
            pipeline.stop()

    def __repr__(self) -> str:
        frames = "?" if self._length is None else self._length  # counting needs a full pass
        return (
            f"RealSenseSource({str(self.path)!r}, frames={frames}, "
            f"{self.intrinsics.width}x{self.intrinsics.height}, depth_scale={self.depth_scale:g})"
        )

    def __len__(self) -> int:
        """The number of depth frames (the first call plays the recording through once)."""
        if self._length is None:
            self._length = sum(1 for _ in self._frames())
        return self._length

    def __iter__(self) -> Iterator[DepthFrame | UnreadableFrame]:
        count = 0
        for index, stamp, raw, message in self._frames():
            count += 1
            source = f"{self.path}#{index}"
            if raw is None or raw.shape != self.intrinsics.shape:
                why = message or f"depth of shape {None if raw is None else raw.shape}"
                yield UnreadableFrame(index, source, why)
                continue
            yield self._frame(raw, index=index, timestamp=stamp, source=source)
        self._length = count
