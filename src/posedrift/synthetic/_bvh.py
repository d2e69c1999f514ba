"""BVH reading and forward kinematics, vectorized over frames.

A BVH file has a ``HIERARCHY`` (joints with an ``OFFSET`` from their parent, a
``CHANNELS`` list, and ``End Site`` leaves) and a ``MOTION`` block (one line of
channel values per frame). This module parses both with line numbers kept for
error messages and computes world positions of every node for all frames at once.

Conventions (the Biovision format as written by MotionBuilder, CMU, Blender):

- rotation channels are in degrees and compose in the order the file lists them,
  ``CHANNELS 3 Zrotation Xrotation Yrotation`` giving ``R = Rz @ Rx @ Ry`` acting on
  column vectors (child to parent);
- a joint's position in its parent's frame is its ``OFFSET``, except where the joint
  has position channels: those values then replace the ``OFFSET`` (axis by axis) as
  the translation from the parent (the reading of Blender and bvhio, which agree with
  this module on the development clips);
- ``End Site`` blocks become leaf nodes named ``<parent>/End Site`` with no channels.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

END_SITE_SUFFIX = "/End Site"
_ROTATIONS = ("Xrotation", "Yrotation", "Zrotation")
_POSITIONS = ("Xposition", "Yposition", "Zposition")
_VALID_CHANNELS = frozenset(_ROTATIONS + _POSITIONS)


@dataclass(frozen=True, eq=False)
class BvhData:
    """A parsed BVH file: the hierarchy and the raw channel values.

    Parameters
    ----------
    names : tuple of str
        Node names in file (depth-first) order; end sites are ``<parent>/End Site``.
    parents : tuple of int
        Parent index per node, -1 for the root. Parents precede children.
    offsets : (N, 3) float
        ``OFFSET`` of each node in its parent's frame, file units.
    channels : tuple of tuple of str
        The channel names of each node in file order (empty for end sites).
    motion : (T, C) float
        Channel values per frame, columns in file order (degrees and file units).
    frame_time : float
        Seconds per frame.
    source : str
        The file the data came from (for messages).
    """

    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray
    channels: tuple[tuple[str, ...], ...]
    motion: np.ndarray
    frame_time: float
    source: str = "<string>"
    _columns: tuple[int, ...] = field(default=(), init=False, repr=False)

    def __post_init__(self) -> None:
        starts, column = [], 0
        for chans in self.channels:
            starts.append(column)
            column += len(chans)
        object.__setattr__(self, "_columns", tuple(starts))

    @property
    def n_frames(self) -> int:
        """Number of frames T."""
        return int(self.motion.shape[0])

    @property
    def fps(self) -> float:
        """Frames per second, ``1 / frame_time``, snapped to the nearest integer when
        within 0.05 % of it (files write ``Frame Time: 0.016667`` for 60 fps)."""
        fps = 1.0 / self.frame_time
        nearest = round(fps)
        return float(nearest) if nearest > 0 and abs(fps - nearest) <= 5e-4 * nearest else fps

    def index(self, name: str) -> int:
        """Index of the node called ``name``; KeyError if absent."""
        return self.names.index(name)

    def _local(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        t = self.n_frames
        r = np.broadcast_to(np.eye(3), (t, 3, 3))
        p = np.broadcast_to(self.offsets[i], (t, 3)).copy()
        start = self._columns[i]
        for c, name in enumerate(self.channels[i]):
            values = self.motion[:, start + c]
            if name in _POSITIONS:
                p[:, _POSITIONS.index(name)] = values  # replaces that axis of the OFFSET
            else:
                r = r @ _axis_rotation(_ROTATIONS.index(name), values)
        return np.array(r), p

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations and positions of every node for every frame.

        Returns
        -------
        rotations : (T, N, 3, 3) float
            Node-to-world rotation.
        positions : (T, N, 3) float
            World positions in file units and file axes.
        """
        t, n = self.n_frames, len(self.names)
        rot = np.empty((t, n, 3, 3))
        pos = np.empty((t, n, 3))
        for i, parent in enumerate(self.parents):
            r_local, p_local = self._local(i)
            if parent < 0:
                rot[:, i], pos[:, i] = r_local, p_local
            else:
                rot[:, i] = rot[:, parent] @ r_local
                pos[:, i] = pos[:, parent] + np.einsum("tij,tj->ti", rot[:, parent], p_local)
        return rot, pos

    def positions(self, names: list[str] | tuple[str, ...] | None = None) -> np.ndarray:
        """World positions of the named nodes (all by default), ``(T, K, 3)`` file units.

        Only the nodes on the paths from the root to the named ones are computed.

        Examples
        --------
        >>> bvh = parse_bvh(EXAMPLE_BVH)
        >>> bvh.positions(["Head"])[0, 0].tolist()
        [0.0, 15.0, 0.0]
        """
        if names is None:
            return self.global_transforms()[1]
        wanted = [self.index(n) for n in names]
        needed: set[int] = set()
        for i in wanted:
            while i >= 0 and i not in needed:
                needed.add(i)
                i = self.parents[i]
        order = sorted(needed)
        slot = {i: k for k, i in enumerate(order)}
        t = self.n_frames
        rot = np.empty((t, len(order), 3, 3))
        pos = np.empty((t, len(order), 3))
        for k, i in enumerate(order):
            r_local, p_local = self._local(i)
            parent = self.parents[i]
            if parent < 0:
                rot[:, k], pos[:, k] = r_local, p_local
            else:
                q = slot[parent]
                rot[:, k] = rot[:, q] @ r_local
                pos[:, k] = pos[:, q] + np.einsum("tij,tj->ti", rot[:, q], p_local)
        return pos[:, [slot[i] for i in wanted]]


def _axis_rotation(axis: int, degrees: np.ndarray) -> np.ndarray:
    """``(T, 3, 3)`` right-handed rotations about one axis (0 x, 1 y, 2 z)."""
    a = np.radians(degrees)
    c, s = np.cos(a), np.sin(a)
    m = np.zeros((len(a), 3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    m[:, axis, axis] = 1.0
    m[:, i, i] = c
    m[:, j, j] = c
    m[:, i, j] = -s
    m[:, j, i] = s
    return m


class _Tokens:
    """Hierarchy tokens with their line numbers."""

    def __init__(self, lines: list[str], source: str) -> None:
        self.items: list[tuple[str, int]] = []
        self.source = source
        self.motion_line = None
        for number, line in enumerate(lines, start=1):
            words = line.split()
            if words and words[0] == "MOTION":
                self.motion_line = number
                break
            self.items.extend((w, number) for w in words)
        self.pos = 0

    def error(self, message: str, line: int | None = None) -> ValueError:
        if line is None:
            line = self.items[min(self.pos, len(self.items) - 1)][1] if self.items else 1
        return ValueError(f"{self.source}, line {line}: {message}")

    def next(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.items):
            last = self.items[-1][1] if self.items else 1
            raise self.error(f"the hierarchy ends early (expected {what}).", last)
        item = self.items[self.pos]
        self.pos += 1
        return item

    def expect(self, word: str) -> int:
        got, line = self.next(repr(word))
        if got != word:
            raise self.error(f"expected {word!r}, got {got!r}.", line)
        return line

    def number(self, what: str) -> float:
        got, line = self.next(what)
        try:
            value = float(got)
        except ValueError:
            raise self.error(f"expected a number for {what}, got {got!r}.", line) from None
        if not np.isfinite(value):
            raise self.error(f"{what} is not finite ({got!r}).", line)
        return value


def parse_bvh(text: str, *, source: str = "<string>") -> BvhData:
    """Parse BVH text.

    Parameters
    ----------
    text : str
        The whole file's content (a leading UTF-8 byte-order mark is ignored).
    source : str
        A name for the text (the file path) used in error messages.

    Returns
    -------
    BvhData

    Raises
    ------
    ValueError
        On a malformed hierarchy, a missing or truncated ``MOTION`` block, a frame
        count that does not match the data, or non-finite channel values; the message
        names ``source`` and the line (and frame) at fault.

    Examples
    --------
    >>> bvh = parse_bvh(EXAMPLE_BVH)
    >>> bvh.names
    ('Hips', 'Spine', 'Head', 'Head/End Site')
    >>> bvh.n_frames, bvh.fps
    (2, 25.0)
    """
    # a UTF-8 byte-order mark (some exporters write one) is not part of the text
    lines = text.removeprefix("\ufeff").splitlines()
    tokens = _Tokens(lines, source)
    if not tokens.items or tokens.items[0][0] != "HIERARCHY":
        raise tokens.error("a BVH file must start with 'HIERARCHY'.", 1)
    tokens.pos = 1
    names: list[str] = []
    parents: list[int] = []
    offsets: list[tuple[float, float, float]] = []
    channels: list[tuple[str, ...]] = []

    def read_node(kind: str, parent: int) -> None:
        if kind == "End":
            tokens.expect("Site")
            if parent < 0:
                raise tokens.error("an 'End Site' cannot be the root.")
            name = names[parent] + END_SITE_SUFFIX
        else:
            name, line = tokens.next("a joint name")
            if name == "{":
                raise tokens.error(f"the {kind} has no name.", line)
            if name in names:
                raise tokens.error(f"the joint name {name!r} appears twice.", line)
        tokens.expect("{")
        index = len(names)
        names.append(name)
        parents.append(parent)
        tokens.expect("OFFSET")
        offsets.append(tuple(tokens.number(f"the OFFSET of {name!r}") for _ in range(3)))
        chans: tuple[str, ...] = ()
        if kind != "End":
            _, line = tokens.next("'CHANNELS'")
            if tokens.items[tokens.pos - 1][0] != "CHANNELS":
                raise tokens.error(f"expected 'CHANNELS' for joint {name!r}.", line)
            count = tokens.number(f"the channel count of {name!r}")
            if count != int(count) or not 0 <= count <= 6:
                raise tokens.error(f"joint {name!r} has a channel count of {count:g}.", line)
            read: list[str] = []
            for _ in range(int(count)):
                chan, line = tokens.next(f"a channel of {name!r}")
                if chan not in _VALID_CHANNELS:
                    raise tokens.error(f"unknown channel {chan!r} for joint {name!r}.", line)
                if chan in read:
                    raise tokens.error(f"channel {chan!r} repeats for joint {name!r}.", line)
                read.append(chan)
            chans = tuple(read)
        channels.append(chans)
        while True:
            word, line = tokens.next(f"'}}' closing {name!r}")
            if word == "}":
                break
            if word == "JOINT" and kind != "End":
                read_node("JOINT", index)
            elif word == "End" and kind != "End":
                read_node("End", index)
            else:
                raise tokens.error(f"unexpected {word!r} inside {name!r}.", line)

    tokens.expect("ROOT")
    read_node("ROOT", -1)
    if tokens.pos != len(tokens.items):
        word, line = tokens.items[tokens.pos]
        raise tokens.error(
            f"unexpected {word!r} after the root joint (one ROOT is supported).", line
        )
    if tokens.motion_line is None:
        raise ValueError(f"{source}: no 'MOTION' section (the file is truncated or not a BVH).")
    labels = [f"{n} {c}" for n, chans in zip(names, channels, strict=True) for c in chans]
    motion, frame_time = _parse_motion(lines, tokens.motion_line, labels, source)
    return BvhData(
        names=tuple(names),
        parents=tuple(parents),
        offsets=np.array(offsets, dtype=float).reshape(-1, 3),
        channels=tuple(channels),
        motion=motion,
        frame_time=frame_time,
        source=source,
    )


def _parse_motion(
    lines: list[str], motion_line: int, labels: list[str], source: str
) -> tuple[np.ndarray, float]:
    """The ``MOTION`` block: ``Frames:``, ``Frame Time:`` and the data lines.

    ``labels`` names each channel column (``"joint channel"``) for messages.
    """
    n_channels = len(labels)
    header: dict[str, tuple[str, int]] = {}
    number = motion_line  # 1-based line of 'MOTION'; lines[number] is the next line
    while number < len(lines) and len(header) < 2:
        line = lines[number].strip()
        number += 1
        if not line:
            continue
        key, _, value = line.partition(":")
        key = " ".join(key.split())
        if key not in ("Frames", "Frame Time"):
            raise ValueError(
                f"{source}, line {number}: expected 'Frames:' and 'Frame Time:' after "
                f"'MOTION', got {line[:40]!r}."
            )
        header[key] = (value.strip(), number)
    if len(header) < 2:
        raise ValueError(f"{source}: the MOTION header is truncated (no 'Frames:'/'Frame Time:').")
    try:
        n_frames = int(header["Frames"][0])
    except ValueError:
        raise ValueError(
            f"{source}, line {header['Frames'][1]}: 'Frames:' is not an integer "
            f"({header['Frames'][0]!r})."
        ) from None
    try:
        frame_time = float(header["Frame Time"][0])
    except ValueError:
        frame_time = float("nan")
    if not (np.isfinite(frame_time) and frame_time > 0):
        raise ValueError(
            f"{source}, line {header['Frame Time'][1]}: 'Frame Time:' must be a positive "
            f"number of seconds, got {header['Frame Time'][0]!r}."
        )
    if n_frames < 1:
        raise ValueError(f"{source}, line {header['Frames'][1]}: 'Frames:' is {n_frames}.")
    data_lines: list[int] = []
    rows: list[list[str]] = []
    for k in range(number, len(lines)):
        words = lines[k].split()
        if not words:
            continue
        if len(words) != n_channels:
            raise ValueError(
                f"{source}, line {k + 1} (frame {len(rows)}): {len(words)} values, expected "
                f"{n_channels} (one per channel of the hierarchy); the data is truncated "
                f"or malformed."
            )
        data_lines.append(k + 1)
        rows.append(words)
    if len(rows) != n_frames:
        raise ValueError(
            f"{source}: 'Frames: {n_frames}' (line {header['Frames'][1]}) but the file holds "
            f"{len(rows)} frame(s) of data; the file is truncated or the count is wrong."
        )
    try:
        motion = np.array(rows, dtype=float).reshape(n_frames, n_channels)
    except ValueError:
        for frame, words in enumerate(rows):
            for word in words:
                try:
                    float(word)
                except ValueError:
                    raise ValueError(
                        f"{source}, line {data_lines[frame]} (frame {frame}): "
                        f"{word!r} is not a number."
                    ) from None
        raise
    bad = ~np.isfinite(motion)
    if bad.any():
        frame, column = (int(v) for v in np.argwhere(bad)[0])
        raise ValueError(
            f"{source}, line {data_lines[frame]} (frame {frame}): channel {column} "
            f"({labels[column]}) is {float(motion[frame, column])}; BVH channel values must "
            f"be finite "
            f"({int(bad.any(axis=1).sum())} frame(s) affected)."
        )
    return motion, frame_time


def load_bvh(path: str | os.PathLike) -> BvhData:
    """Read a BVH file.

    Parameters
    ----------
    path : str or path-like
        The ``.bvh`` file.

    Returns
    -------
    BvhData
        The hierarchy and raw channel values; :meth:`BvhData.positions` gives
        forward kinematics in file units and axes.

    Raises
    ------
    ValueError
        If the file cannot be read or is malformed (the message names the file
        and the line or frame).
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig", errors="replace")
    except OSError as exc:
        raise ValueError(f"Cannot read BVH file {str(path)!r}: {exc}") from exc
    return parse_bvh(text, source=str(path))


EXAMPLE_BVH = """HIERARCHY
ROOT Hips
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation
  JOINT Spine
  {
    OFFSET 0 10 0
    CHANNELS 3 Zrotation Xrotation Yrotation
    JOINT Head
    {
      OFFSET 0 5 0
      CHANNELS 3 Zrotation Xrotation Yrotation
      End Site
      {
        OFFSET 0 3 0
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.04
0 0 0 0 0 0 0 0 0 0 0 0
1 0 0 90 0 0 0 0 0 0 0 0
"""
"""A tiny BVH text for examples and tests."""
