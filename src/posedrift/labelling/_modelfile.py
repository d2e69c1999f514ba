"""The learned models' files: versioned ``.npz`` archives of plain arrays.

One reader for the body-part forest's and the body-part net's files: the bytes of a
file or of a model shipped in ``posedrift/data``, the archive's arrays read without
unpickling, and the header every model file carries (format name and version, the
part names it was trained for, its JSON metadata). Each message names the file.
"""

from __future__ import annotations

import io
import json
import zipfile
from collections.abc import Sequence
from importlib import resources
from os import PathLike
from pathlib import Path

import numpy as np

from posedrift.skeleton import PART_NAMES


def read_model_file(path: str | PathLike, what: str) -> bytes:
    """The bytes of the ``what`` file at ``path`` (``what``: "forest model", ...).

    Raises
    ------
    ValueError
        If the file cannot be read, naming it.
    """
    path = Path(path)
    try:
        return path.read_bytes()
    except OSError as exc:
        raise ValueError(f"Cannot read the {what} file {path}: {exc}.") from exc


def read_packaged_model(name: str, what: str, command: str) -> bytes:
    """The bytes of the model ``posedrift/data/<name>``.

    Raises
    ------
    ValueError
        If the package lacks it, saying which ``command`` trains one.
    """
    resource = resources.files("posedrift").joinpath("data", name)
    try:
        return resource.read_bytes()
    except (FileNotFoundError, OSError) as exc:
        raise ValueError(
            f"The default {what} {name} is missing from the posedrift package; train one "
            f"with '{command} --out MODEL'."
        ) from exc


def open_archive(data: bytes, prefix: str) -> dict[str, np.ndarray]:
    """Every array of an ``.npz`` archive, read with ``allow_pickle=False``.

    ``prefix`` starts every message (``"The forest model file x.npz"``).

    Raises
    ------
    ValueError
        If the bytes are no zip archive, are truncated, or hold an object array.
    """
    if not data.startswith(b"PK"):
        raise ValueError(f"{prefix} is truncated or corrupt: not an .npz archive (a zip file).")
    try:
        with np.load(io.BytesIO(data), allow_pickle=False) as npz:
            return {k: npz[k] for k in npz.files}
    except ValueError as exc:
        raise ValueError(f"{prefix} cannot be read safely: {exc}") from exc
    except (OSError, EOFError, KeyError, zipfile.BadZipFile) as exc:
        raise ValueError(f"{prefix} is truncated or corrupt: {exc}") from exc


def text_scalar(value: np.ndarray) -> str:
    """The text of a 0-d string array.

    Raises
    ------
    ValueError
        If ``value`` is not one.
    """
    if value.shape != () or value.dtype.kind != "U":
        raise ValueError(f"expected a text scalar, got {value.dtype} of shape {value.shape}")
    return str(value)


def check_header(
    arrays: dict[str, np.ndarray],
    prefix: str,
    *,
    kind: str,
    format_name: str,
    version: int,
    command: str,
    required: Sequence[str],
) -> dict:
    """Check a model file's header and keys; return its metadata.

    Parameters
    ----------
    arrays : dict of str to array
        From :func:`open_archive`.
    prefix : str
        Starts every message.
    kind : str
        What the file should be ("forest", "body-part net").
    format_name, version : str, int
        Its expected ``format`` and ``version``.
    command : str
        The command that retrains one (named when the version differs).
    required : sequence of str
        Keys the file must hold, besides ``format`` and ``version``.

    Raises
    ------
    ValueError
        If the format, the version, a key, the part names or the metadata is not what
        this posedrift reads.
    """
    if "format" in arrays and "version" in arrays:
        try:
            fmt = text_scalar(arrays["format"])
        except ValueError:
            fmt = None
        if fmt != format_name:
            raise ValueError(f"{prefix} is not a posedrift {kind} (format {fmt!r}).")
        found = arrays["version"]
        if found.shape != () or not np.issubdtype(found.dtype, np.integer):
            raise ValueError(f"{prefix} has an unreadable format version.")
        if int(found) != version:
            raise ValueError(
                f"{prefix} has format version {int(found)}; this posedrift reads version "
                f"{version}. Retrain it with '{command}'."
            )
    missing = [k for k in ("format", "version", *required) if k not in arrays]
    if missing:
        raise ValueError(f"{prefix} is not a posedrift {kind}: missing {missing}.")
    parts = arrays["part_names"]
    if parts.dtype.kind != "U" or tuple(parts.tolist()) != PART_NAMES:
        raise ValueError(f"{prefix} was trained for other body parts: {parts.tolist()!r}.")
    try:
        metadata = json.loads(text_scalar(arrays["metadata"]))
    except (json.JSONDecodeError, ValueError) as exc:
        raise ValueError(f"{prefix} has unreadable metadata: {exc}") from exc
    if not isinstance(metadata, dict):
        raise ValueError(f"{prefix} has unreadable metadata (not an object).")
    return metadata


def float_scalars(arrays: dict[str, np.ndarray], names: Sequence[str], prefix: str) -> dict:
    """The named 0-d float arrays as floats.

    Raises
    ------
    ValueError
        If one is not a 0-d float array.
    """
    out = {}
    for name in names:
        value = arrays[name]
        if value.shape != () or value.dtype.kind != "f":
            raise ValueError(f"{prefix} has a malformed '{name}' ({value.dtype}, {value.shape}).")
        out[name] = float(value)
    return out
