"""Intel RealSense recordings (``.bag`` ROS1, ``.db3`` ROS2) through ``pyrealsense2`` playback.

librealsense plays a recording on its own threads, and those threads can abort the whole
process while they shut down (seen on loaded machines, after every frame was delivered).
So the playback runs in a child process (``python -m posedrift.io._realsense FILE MODE``) that
sends the stream's description and then each depth frame through a pipe, and leaves with
``os._exit`` once done, skipping librealsense's teardown. A child that dies early costs
only the frames it had not sent: the source reports the rest as one unreadable frame.
"""

from __future__ import annotations

import os
import pickle
import signal
import subprocess
import sys
import tempfile
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
    except ModuleNotFoundError as exc:
        raise ImportError(
            "Reading RealSense recordings needs pyrealsense2: pip install 'posedrift[realsense]'."
        ) from exc
    except ImportError as exc:  # installed, but a system library it links to is missing
        raise ImportError(
            f"pyrealsense2 is installed but cannot load ({exc}). Its wheel needs libusb-1.0: "
            "on Debian or Ubuntu, apt-get install libusb-1.0-0."
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
        _import_realsense()  # a missing package is said here, not by the child
        stream = _describe(self.path)
        self.fps = float(stream["fps"] or fps)
        self.depth_scale = resolve_depth_scale(
            depth_scale, default=float(f"{1.0 / float(stream['units']):.6g}")
        )
        if camera is None and intrinsics is None:
            self.intrinsics = Intrinsics(*stream["intrinsics"])
        else:
            self.intrinsics = resolve_intrinsics(
                (stream["height"], stream["width"]),
                camera=camera,
                intrinsics=intrinsics,
                where=str(self.path),
            )
        self._set_unmirror(unmirror)
        self._length: int | None = None

    def _frames(self, mode: str = "frames") -> Iterator[tuple[int, float, np.ndarray | None, str]]:
        """``(index, timestamp_s, raw or None, message)`` for each depth frame.

        ``mode="count"`` plays the recording without sending its pixels (``raw`` None).
        """
        index = 0
        for message in _play(self.path, mode):
            if message[0] == "frame":
                yield message[1:]
                index += 1
            else:  # "error" (cannot start) or "died": the rest of the recording is lost
                yield index, float("nan"), None, message[1]
                return

    def __repr__(self) -> str:
        frames = "?" if self._length is None else self._length  # counting needs a full pass
        return (
            f"RealSenseSource({str(self.path)!r}, frames={frames}, "
            f"{self.intrinsics.width}x{self.intrinsics.height}, depth_scale={self.depth_scale:g})"
        )

    def __len__(self) -> int:
        """The number of depth frames (the first call plays the recording through once)."""
        if self._length is None:
            self._length = sum(1 for _ in self._frames("count"))
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


# -- the parent's side of the pipe --------------------------------------------------------------


def _describe(path: Path) -> dict:
    """The recording's depth stream: intrinsics, size, fps and depth units."""
    for message in _play(path, "describe"):
        if message[0] == "stream":
            return message[1]
        if message[0] == "error":
            raise ValueError(message[1])
        if message[0] == "died":
            raise ValueError(
                f"Cannot play back the RealSense recording {str(path)!r}: {message[1]}"
            )
    raise ValueError(f"Cannot play back the RealSense recording {str(path)!r}: no stream found.")


def _child_command(path: Path, mode: str) -> list[str]:
    return [sys.executable, "-m", "posedrift.io._realsense", str(path), mode]


def _play(path: Path, mode: str) -> Iterator[tuple]:
    """The child's messages, in order; ``("died", why)`` last if it ended before its ``end``."""
    stderr_file = tempfile.TemporaryFile()  # a file, not a pipe: a chatty child cannot block
    child = subprocess.Popen(_child_command(path, mode), stdout=subprocess.PIPE, stderr=stderr_file)
    finished = False
    try:
        while True:
            try:
                message = pickle.load(child.stdout)
            except EOFError:
                break
            if message[0] == "end":
                finished = True
                break
            yield message
    finally:
        child.stdout.close()
        if finished:
            child.wait()
        else:  # the consumer stopped early, or the child died: either way it is done
            child.kill()
            child.wait()
        stderr_file.seek(0)
        stderr = stderr_file.read().decode(errors="replace").strip()
        stderr_file.close()
    if not finished:
        yield ("died", _death(child.returncode, stderr))


def _death(returncode: int, stderr: str) -> str:
    how = f"signal {signal.Signals(-returncode).name}" if returncode < 0 else f"exit {returncode}"
    last = stderr.splitlines()[-1] if stderr else "no message"
    return f"librealsense playback stopped early ({how}: {last})"


# -- the child: librealsense playback -------------------------------------------------------------


def _serve(path: str, mode: str) -> None:
    """Play ``path`` and pickle to standard output what ``mode`` asks for.

    ``"describe"``: the depth stream; ``"count"``: one message per depth frame, without
    its pixels; ``"frames"``: each depth frame.
    """
    out = sys.stdout.buffer
    rs = _import_realsense()
    config = rs.config()
    try:
        config.enable_device_from_file(path, repeat_playback=False)
        config.enable_all_streams()
        pipeline = rs.pipeline()
        profile = pipeline.start(config)
    except RuntimeError as exc:
        message = f"Cannot play back the RealSense recording {path!r}: {exc}"
        pickle.dump(("error", message), out)
        pickle.dump(("end",), out)
        return
    playback = profile.get_device().as_playback()
    playback.set_real_time(False)
    if mode == "describe":
        pickle.dump(_stream(rs, path, profile), out)
    else:
        _send_frames(rs, pipeline, playback, out, pixels=mode == "frames")
    pipeline.stop()
    pickle.dump(("end",), out)


def _stream(rs, path: str, profile) -> tuple:
    streams = list(profile.get_streams())
    depth = [s for s in streams if s.stream_type() == rs.stream.depth]
    if not depth:
        found = ", ".join(str(s.stream_type()).split(".")[-1] for s in streams) or "none"
        return ("error", f"The recording {path!r} has no depth stream. Streams found: {found}.")
    video = depth[0].as_video_stream_profile()
    own = video.get_intrinsics()
    try:
        units = profile.get_device().first_depth_sensor().get_depth_scale()
    except RuntimeError:
        units = 0.001
    return (
        "stream",
        {
            "intrinsics": (own.fx, own.fy, own.ppx, own.ppy, own.width, own.height),
            "width": own.width,
            "height": own.height,
            "fps": video.fps(),
            "units": units,
        },
    )


def _send_frames(rs, pipeline, playback, out, *, pixels: bool) -> None:
    first = None
    index = 0
    while True:
        ok, frames = pipeline.try_wait_for_frames(_WAIT_MS)
        if not ok:
            break
        depth = frames.get_depth_frame()
        if not depth:
            continue
        stamp_ms = depth.get_timestamp()
        first = stamp_ms if first is None else first
        raw, message = None, ""
        try:
            if pixels:
                raw = np.array(depth.get_data(), dtype=np.uint16, copy=True)
        except (RuntimeError, ValueError) as exc:
            message = str(exc)
        pickle.dump(("frame", index, (stamp_ms - first) / 1000.0, raw, message), out)
        out.flush()  # the parent tracks each frame as it comes
        index += 1
        if playback.current_status() == rs.playback_status.stopped:
            break


if __name__ == "__main__":
    _serve(sys.argv[1], sys.argv[2])
    sys.stdout.flush()
    os._exit(0)  # librealsense's own teardown is what crashes; nothing is left to tear down
