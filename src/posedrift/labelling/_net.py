"""The body-part net: a multilayer perceptron over depth-comparison features.

Beyond the paper. A tree of the body-part forest reads about twenty of its offset
bank's features along one root-to-leaf path; the net reads every feature of its
bank at once (``K`` depth differences around the pixel, scaled by the pixel's depth
as in Shotton et al.), through a few ReLU layers, into the 15 part probabilities.
It labels held-out synthetic pixels markedly better than the forest trained on the
same frames (``docs/RESULTS.md``), at a few milliseconds for the tracker's points.

The model is plain arrays (no pickled objects): the offset bank, one weight matrix
and one bias vector per layer, and the clipping of the features. Inference needs
NumPy alone; so does training (:func:`fit_perceptron`, a small mini-batch AdamW loop
written here because no light, well-kept library trains a perceptron in float32
with a learning-rate schedule and label smoothing without pulling in a deep-learning
framework).
"""

from __future__ import annotations

import itertools
import json
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from posedrift._validation import check_rng, check_scalar
from posedrift.camera import Intrinsics
from posedrift.labelling._features import (
    BACKGROUND_DEPTH,
    REFERENCE_FOCAL,
    CheckedPixels,
    checked_frame,
    feature_matrix,
    foreground_pixels,
    probed_features,
)
from posedrift.labelling._forest import MAX_OFFSET, PartPrediction
from posedrift.labelling._modelfile import (
    check_header,
    float_scalars,
    open_archive,
    read_model_file,
    read_packaged_model,
)
from posedrift.skeleton import PART_NAMES, other_side

FORMAT_NAME = "posedrift-body-part-net"
FORMAT_VERSION = 1
MAX_LAYERS = 16
"""Most layers a model file may hold."""

_DEFAULT_MODELS = {
    "frontal": "part_net_default.npz",
    "turned": "part_net_turned.npz",
    "high": "part_net_high.npz",
    "back": "part_net_back.npz",
    "side": "part_net_side.npz",
}
"""The shipped nets: trained on views within 45 (30% of them up to 100) degrees of
frontal, on views turned any way (``--wide-share 1 --wide-yaw 180``), on frontal
views from cameras up to 2.4 m high (``--camera-heights 0.7,2.4``), on people
seen from behind (``--wide-min-yaw 120``), and on people showing their left side
(``--wide-left-side``)."""
_TRAIN_COMMANDS = {
    "frontal": "posedrift train --classifier net",
    "turned": "posedrift train --classifier net --wide-share 1 --wide-yaw 180",
    "high": "posedrift train --classifier net --camera-heights 0.7,2.4",
    "back": "posedrift train --classifier net --wide-share 1 --wide-yaw 180 --wide-min-yaw 120",
    "side": "posedrift train --classifier net --wide-share 1 --wide-yaw 165 --wide-min-yaw 30 "
    "--wide-left-side",
}
_KEYS = ("part_names", "metadata", "reference_focal", "background", "clip", "offsets", "n_layers")
"""What a model file holds besides its format, version and layers."""
_LOADED_DEFAULTS: dict[str, BodyPartNet] = {}  # the shipped models, once loaded
_BLOCK = 4096  # pixels per block at inference: bounds the hidden activations' memory


@dataclass(frozen=True, eq=False)
class BodyPartNet:
    """A multilayer perceptron that labels depth pixels with the 15 body parts.

    A pixel's input is its row of :func:`~posedrift.labelling.depth_features` over
    ``offsets`` (metres), clipped to ``[-clip, clip]``; each hidden layer is
    ``max(0, h @ W + b)``; the last layer's softmax gives ``P(part | pixel)``.

    Parameters
    ----------
    offsets : (K, 4) float32
        Offset pairs ``(u_row, u_col, v_row, v_col)`` in pixel x metres at ``reference_focal``.
    weights : sequence of (D_in, D_out) float32
        One matrix per layer: ``(K, H_1)``, ..., ``(H_n, 15)``.
    biases : sequence of (D_out,) float32
    clip : float
        Metres: features beyond it (a probe on background reads 10 m) are clipped.
    reference_focal : float
        Focal length (pixels) of the offsets.
    background : float
        Depth (metres) read by background and off-image probes.
    metadata : mapping
        JSON-serialisable facts about training; read-only.

    Examples
    --------
    >>> net = BodyPartNet.load_default()
    >>> net.n_parts, net.n_features
    (15, 500)
    """

    offsets: np.ndarray
    weights: tuple[np.ndarray, ...]
    biases: tuple[np.ndarray, ...]
    clip: float = 1.0
    reference_focal: float = REFERENCE_FOCAL
    background: float = BACKGROUND_DEPTH
    metadata: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        offsets, weights, biases = _validate(
            self.offsets, self.weights, self.biases, self.clip, self.reference_focal
        )
        for name, value in (("offsets", offsets), ("weights", weights), ("biases", biases)):
            object.__setattr__(self, name, value)
        for name in ("clip", "reference_focal", "background"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))

    @property
    def n_parts(self) -> int:
        """Number of body parts (15)."""
        return int(self.weights[-1].shape[1])

    @property
    def n_features(self) -> int:
        """Number of offset pairs read at each pixel."""
        return len(self.offsets)

    @property
    def hidden(self) -> tuple[int, ...]:
        """Widths of the hidden layers."""
        return tuple(int(w.shape[1]) for w in self.weights[:-1])

    # ------------------------------------------------------------------ inference
    def predict_proba_features(self, features: np.ndarray) -> np.ndarray:
        """Part probabilities ``(N, 15)`` float32 from a feature matrix.

        Parameters
        ----------
        features : (N, K) float
            Column ``k`` is offset pair ``k`` (metres, unclipped). Not modified.
        """
        x = np.asarray(features)
        if x.ndim != 2 or x.shape[1] != self.n_features:
            raise ValueError(
                f"The 'features' argument must be an (N, {self.n_features}) matrix. "
                f"Got shape {x.shape} instead."
            )
        out = np.empty((len(x), self.n_parts), dtype=np.float32)
        for start in range(0, len(x), _BLOCK):
            block = np.array(x[start : start + _BLOCK], dtype=np.float32)  # a copy to clip
            out[start : start + len(block)] = self._classify(block)
        return out

    def predict(
        self, depth: np.ndarray, mask: np.ndarray | None, intrinsics: Intrinsics
    ) -> PartPrediction:
        """Label every foreground pixel of a depth frame with a body part.

        The same contract as :meth:`BodyPartForest.predict
        <posedrift.labelling.BodyPartForest.predict>`.

        Examples
        --------
        >>> import numpy as np
        >>> from posedrift.camera import camera_preset
        >>> cam = camera_preset("kinect1-qvga")
        >>> pred = BodyPartNet.load_default().predict(np.zeros((240, 320)), None, cam)
        >>> pred.labels.shape, pred.probabilities.shape
        ((240, 320), (0, 15))
        """
        depth, valid = checked_frame(depth, mask, intrinsics, "BodyPartNet.predict")
        flat, pixels = foreground_pixels(valid)
        labels = np.full(depth.shape, -1, dtype=np.int16)
        probabilities = np.zeros((len(pixels), self.n_parts), dtype=np.float32)
        for start in range(0, len(pixels), _BLOCK):
            block = pixels[start : start + _BLOCK]
            probabilities[start : start + len(block)] = self._probabilities(
                depth, valid, block, intrinsics
            )
        np.put(labels, flat, np.argmax(probabilities, axis=1).astype(np.int16))
        return PartPrediction(labels=labels, pixels=pixels, probabilities=probabilities)

    def mirrored(self) -> BodyPartNet:
        """The net for the mirror image: it labels a depth image as this net labels the
        image flipped left to right, with every left part read as the right one.

        A net trained on people showing their left side thus reads people showing
        their right side (the features' column offsets negated, the output's left
        and right parts swapped; nothing is retrained).

        Examples
        --------
        >>> import numpy as np
        >>> from posedrift.camera import camera_preset
        >>> cam = camera_preset("kinect1-qvga")
        >>> depth = np.zeros(cam.shape, np.float32); depth[60:200, 120:175] = 2.5
        >>> net = BodyPartNet.load_default()
        >>> flipped = net.predict(depth[:, ::-1].copy(), None, cam).labels[:, ::-1]
        >>> swap = np.array([PART_NAMES.index(other_side(n)) for n in PART_NAMES])
        >>> mirror = net.mirrored().predict(depth, None, cam).labels
        >>> bool(np.array_equal(mirror[depth > 0], swap[flipped[depth > 0]]))
        True
        """
        swap = [PART_NAMES.index(other_side(name)) for name in PART_NAMES]
        offsets = self.offsets * np.array([1, -1, 1, -1], dtype=np.float32)
        weights = (*self.weights[:-1], np.ascontiguousarray(self.weights[-1][:, swap]))
        biases = (*self.biases[:-1], np.ascontiguousarray(self.biases[-1][swap]))
        metadata = {**self.metadata, "mirrored": not self.metadata.get("mirrored", False)}
        return replace(self, offsets=offsets, weights=weights, biases=biases, metadata=metadata)

    def predict_pixels(
        self,
        depth: np.ndarray,
        pixels: np.ndarray,
        intrinsics: Intrinsics,
        *,
        mask: np.ndarray | None = None,
    ) -> np.ndarray:
        """Part probabilities of only the given pixels (the tracker's per-point evidence).

        Each row equals that pixel's row of ``predict(depth, mask, intrinsics)``.

        Returns
        -------
        (N, 15) float32
            ``P(part | pixel)``; a uniform row for a pixel outside the foreground.

        Examples
        --------
        >>> import numpy as np
        >>> from posedrift.camera import camera_preset
        >>> cam = camera_preset("kinect1-qvga")
        >>> depth = np.zeros(cam.shape, np.float32); depth[100:140, 150:170] = 2.5
        >>> net = BodyPartNet.load_default()
        >>> rows = net.predict_pixels(depth, np.array([[120, 160], [0, 0]]), cam)
        >>> rows.shape, bool(np.allclose(rows[1], 1 / 15))  # (0, 0) is background: uniform
        ((2, 15), True)
        """
        checked = CheckedPixels(depth, mask, pixels, intrinsics, "BodyPartNet.predict_pixels")
        return self._predict_checked(checked)

    def _predict_checked(self, checked: CheckedPixels) -> np.ndarray:
        """:meth:`predict_pixels` of :class:`CheckedPixels` (checks and probes shared)."""
        out = np.full((len(checked.pixels), self.n_parts), 1.0 / self.n_parts, dtype=np.float32)
        inside = checked.inside
        if inside.any():
            x = probed_features(
                checked.image(self.background),
                checked.depth.shape,
                checked.terms(self.reference_focal),
                self.offsets,
            )
            out[inside] = self._classify(x)
        return out

    def _probabilities(self, depth, valid, pixels, intrinsics) -> np.ndarray:
        x = feature_matrix(
            depth,
            valid,
            pixels,
            self.offsets,
            intrinsics,
            reference_focal=self.reference_focal,
            background=self.background,
        )
        return self._classify(x)

    def _classify(self, x: np.ndarray) -> np.ndarray:
        """Probabilities of float32 features ``x`` that this call owns (clipped in place)."""
        np.clip(x, -self.clip, self.clip, out=x)
        return _softmax(_forward(x, self.weights, self.biases))

    # ------------------------------------------------------------------ files
    def save(self, path: str | PathLike) -> Path:
        """Write the model to ``path`` (a compressed ``.npz`` of plain arrays).

        Weights are stored as float16 (inference runs in float32); nothing is pickled.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        layers = {}
        for i, (w, b) in enumerate(zip(self.weights, self.biases, strict=True)):
            layers[f"weight_{i}"] = w.astype(np.float16)
            layers[f"bias_{i}"] = b.astype(np.float16)
        with open(path, "wb") as handle:
            np.savez_compressed(
                handle,
                format=np.array(FORMAT_NAME),
                version=np.array(FORMAT_VERSION, dtype=np.int32),
                part_names=np.array(PART_NAMES),
                metadata=np.array(json.dumps(dict(self.metadata), sort_keys=True)),
                reference_focal=np.array(self.reference_focal),
                background=np.array(self.background),
                clip=np.array(self.clip),
                offsets=self.offsets,
                n_layers=np.array(len(self.weights), dtype=np.int32),
                **layers,
            )
        return path

    @classmethod
    def load(cls, path: str | PathLike) -> BodyPartNet:
        """Read a model written by :meth:`save`, checking every array; never unpickles.

        Raises
        ------
        ValueError
            If the file is not a posedrift body-part net, has another format version,
            is truncated or corrupt, or holds arrays of the wrong shape or dtype.
        """
        return cls._from_bytes(read_model_file(path, "body-part net"), str(Path(path)))

    @classmethod
    def load_default(cls, views: str = "frontal") -> BodyPartNet:
        """A model shipped with posedrift.

        Loaded once per process and shared: the model is immutable.

        Parameters
        ----------
        views : {"frontal", "turned", "high", "back", "side"}
            ``"frontal"``: trained on people facing the camera (within 45 degrees,
            and 30% of the frames up to 100), the net that labels the tracker's
            pixels; ``"turned"``: trained on people turned any way, up to their back
            to the camera, which the tracker asks once its skeleton has turned away
            (:class:`FacingNets`). The turned net labels people who face the camera
            less well than the frontal one (0.83 against 0.94 of held-out pixels,
            docs/results-log.md). ``"high"``: the frontal net's training with cameras
            0.7-2.4 m high instead of 0.7-1.3 (half of them aimed at the pelvis),
            asked in the frontal net's place where the camera looks down; on level
            cameras it is the worse of the two (docs/results-log.md). ``"back"``:
            the turned net's training with every view turned 120-180 degrees away, which
            the tracker asks once its skeleton shows the person's back. ``"side"``:
            every view turned 30-165 degrees with the person's left side towards the
            camera; its :meth:`mirrored` twin reads the right side, and the tracker
            asks one of them while its skeleton keeps a side turned to the camera.
        """
        if views not in _DEFAULT_MODELS:
            raise ValueError(
                f"The 'views' parameter of BodyPartNet.load_default must be one of "
                f"{sorted(_DEFAULT_MODELS)}. Got {views!r} instead."
            )
        if views not in _LOADED_DEFAULTS:
            name = _DEFAULT_MODELS[views]
            data = read_packaged_model(name, "body-part net", _TRAIN_COMMANDS[views])
            _LOADED_DEFAULTS[views] = cls._from_bytes(data, f"posedrift/data/{name}")
        return _LOADED_DEFAULTS[views]

    @classmethod
    def _from_bytes(cls, data: bytes, where: str) -> BodyPartNet:
        prefix = f"The body-part net file {where}"
        arrays = open_archive(data, prefix)
        metadata = check_header(
            arrays,
            prefix,
            kind="body-part net",
            format_name=FORMAT_NAME,
            version=FORMAT_VERSION,
            command="posedrift train --classifier net",
            required=_KEYS,
        )
        scalars = float_scalars(arrays, ("reference_focal", "background", "clip"), prefix)
        n_layers = arrays["n_layers"]
        if (
            n_layers.shape != ()
            or n_layers.dtype.kind not in "iu"
            or not 1 <= n_layers <= MAX_LAYERS
        ):
            raise ValueError(f"{prefix} has a malformed layer count.")
        names = [f"{kind}_{i}" for i in range(int(n_layers)) for kind in ("weight", "bias")]
        missing = [k for k in names if k not in arrays]
        if missing:
            raise ValueError(f"{prefix} is not a posedrift body-part net: missing {missing}.")
        for name in ("offsets", *names):
            if arrays[name].dtype.kind != "f":
                raise ValueError(
                    f"{prefix} has '{name}' of dtype {arrays[name].dtype}; expected float."
                )
        try:
            return cls(
                offsets=arrays["offsets"],
                weights=tuple(arrays[f"weight_{i}"] for i in range(int(n_layers))),
                biases=tuple(arrays[f"bias_{i}"] for i in range(int(n_layers))),
                metadata=metadata,
                **scalars,
            )
        except ValueError as exc:
            raise ValueError(f"{prefix} is invalid: {exc}") from exc


@dataclass(frozen=True, eq=False)
class FacingNets:
    """Body-part nets, one chosen by which way the person faces the camera.

    Beyond the paper. A net trained on frontal views labels a person seen from
    behind as their mirror image; one trained on every view also reads real people
    who face the camera as seen from behind (docs/results-log.md). The tracker therefore
    asks ``frontal`` while its last skeleton faces the camera, and ``turned`` once
    that skeleton has turned more than ``turn_gate`` degrees away
    (:func:`posedrift.skeleton.facing_yaw`). Where nothing tells which way the
    person faces (a per-frame method, the first frame), it labels as ``frontal``.
    Where ``high`` is given and the camera looks down more than ``high_gate``
    degrees (the tracker measures the tilt at calibration,
    :func:`posedrift.tracking.world_up`), ``high`` takes the frontal net's place.
    Where ``back`` is given and the skeleton has turned more than ``back_gate``
    degrees, the person shows their back and ``back`` labels: a net that saw only
    backs need not tell a back from a front, which decides left from right. Where
    ``side`` is given and the caller knows which side the person shows (the tracker:
    a skeleton that has kept one side towards the camera), ``side`` or its
    :meth:`~BodyPartNet.mirrored` twin takes the turned net's place, for the same
    reason: a net that saw only left sides need not tell them from right ones.

    Parameters
    ----------
    frontal, turned : BodyPartNet
        Or anything with the net's ``predict`` and ``predict_pixels``.
    turn_gate : float
        Degrees in [0, 180].
    high : BodyPartNet, optional
        The frontal views' net for a camera mounted high and looking down.
    high_gate : float
        Degrees in [0, 90]: the shipped frontal net saw cameras up to about 8 degrees
        off level, and real recordings from a level camera read up to 7.
    back : BodyPartNet, optional
        The net for a person seen from behind.
    back_gate : float
        Degrees in [0, 180]. The shipped back net saw turns of 120-180 degrees; the
        gate sits further out because the skeleton's own facing lags a turn (on the
        development clips 135 and 145 cost, 155 and 165 gained: docs/results-log.md).
    side : BodyPartNet, optional
        The net for a person turned with their left side towards the camera (anything
        with the net's ``mirrored``): the shipped side net saw turns of 30-165 degrees.
    side_gate : float
        Degrees in [0, 180]: the side nets label only beyond it (and up to
        ``back_gate``). The skeleton's facing lags a turn towards the side, where the
        side net cost the held-out hop 131_03 at 45 degrees (docs/results-log.md).

    Examples
    --------
    >>> nets = FacingNets.load_default()
    >>> nets.select(10.0) is nets.frontal, nets.select(120.0) is nets.turned
    (True, True)
    >>> nets.select(float("nan")) is nets.frontal  # no skeleton to tell
    True
    >>> nets.select(10.0, tilt=24.0) is nets.high  # a camera looking 24 degrees down
    True
    >>> nets.select(170.0) is nets.back  # the person's back to the camera
    True
    >>> nets.select(90.0, side="left") is nets.side  # the left side to the camera
    True
    >>> nets.select(90.0, side="right").metadata["mirrored"]  # the side net's mirror image
    True
    """

    frontal: Any
    turned: Any
    turn_gate: float = 45.0
    high: Any = None
    high_gate: float = 12.0
    back: Any = None
    back_gate: float = 155.0
    side: Any = None
    side_gate: float = 60.0

    def __post_init__(self) -> None:
        gates = (("turn_gate", 180.0), ("high_gate", 90.0), ("back_gate", 180.0))
        for name, top in (*gates, ("side_gate", 180.0)):
            gate = check_scalar(
                getattr(self, name),
                name,
                low=0.0,
                high=top,
                include_low=True,
                include_high=True,
                caller="FacingNets",
            )
            object.__setattr__(self, name, float(gate))
        right = None if self.side is None else self.side.mirrored()
        object.__setattr__(self, "_right_side", right)

    @classmethod
    def load_default(cls, turn_gate: float = 45.0) -> FacingNets:
        """The shipped frontal, turned, high, back and side nets
        (:meth:`BodyPartNet.load_default`)."""
        return cls(
            BodyPartNet.load_default("frontal"),
            BodyPartNet.load_default("turned"),
            turn_gate=turn_gate,
            high=BodyPartNet.load_default("high"),
            back=BodyPartNet.load_default("back"),
            side=BodyPartNet.load_default("side"),
        )

    def select(
        self, facing_yaw: float | None, *, tilt: float | None = None, side: str | None = None
    ) -> Any:
        """The net for a person turned ``facing_yaw`` degrees away (None, NaN: frontal),
        seen by a camera looking ``tilt`` degrees down (None: level), showing their
        ``side`` (``"left"`` or ``"right"``; None: not known) to the camera."""
        if side not in (None, "left", "right"):
            raise ValueError(
                f"The 'side' parameter of FacingNets.select must be 'left', 'right' or "
                f"None. Got {side!r} instead."
            )
        if facing_yaw is not None:  # NaN compares False below
            if self.back is not None and facing_yaw > self.back_gate:
                return self.back
            if facing_yaw > self.turn_gate:
                if self.side is not None and side is not None and facing_yaw > self.side_gate:
                    return self.side if side == "left" else self._right_side
                return self.turned
        if self.high is not None and tilt is not None and tilt > self.high_gate:
            return self.high
        return self.frontal

    def predict(
        self, depth: np.ndarray, mask: np.ndarray | None, intrinsics: Intrinsics
    ) -> PartPrediction:
        """``frontal``'s :meth:`BodyPartNet.predict`."""
        return self.frontal.predict(depth, mask, intrinsics)

    def predict_pixels(
        self,
        depth: np.ndarray,
        pixels: np.ndarray,
        intrinsics: Intrinsics,
        *,
        mask: np.ndarray | None = None,
    ) -> np.ndarray:
        """``frontal``'s :meth:`BodyPartNet.predict_pixels`."""
        return self.frontal.predict_pixels(depth, pixels, intrinsics, mask=mask)


def _validate(offsets, weights, biases, clip, reference_focal):
    """Shapes, dtypes and finiteness of a net's arrays; contiguous float32 copies."""
    offsets = np.asarray(offsets)
    if offsets.ndim != 2 or offsets.shape[1] != 4 or len(offsets) == 0:
        raise ValueError(f"The 'offsets' of BodyPartNet must be (K, 4). Got {offsets.shape}.")
    if not np.all(np.isfinite(offsets)) or np.abs(offsets).max() > MAX_OFFSET:
        raise ValueError(
            f"The 'offsets' of BodyPartNet must be finite and within +-{MAX_OFFSET:g} "
            f"pixel x metres."
        )
    if len(weights) != len(biases) or not 1 <= len(weights) <= MAX_LAYERS:
        raise ValueError(
            f"A BodyPartNet needs 1 to {MAX_LAYERS} layers, one bias per weight matrix. "
            f"Got {len(weights)} weights and {len(biases)} biases."
        )
    width = len(offsets)
    checked_w, checked_b = [], []
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        w, b = np.asarray(w), np.asarray(b)
        if w.ndim != 2 or w.shape[0] != width or b.shape != (w.shape[1],):
            raise ValueError(
                f"Layer {i} of BodyPartNet must map {width} inputs: a ({width}, D) weight "
                f"matrix and a (D,) bias. Got {w.shape} and {b.shape}."
            )
        if not (np.all(np.isfinite(w)) and np.all(np.isfinite(b))):
            raise ValueError(f"Layer {i} of BodyPartNet has non-finite weights.")
        checked_w.append(np.ascontiguousarray(w, dtype=np.float32))
        checked_b.append(np.ascontiguousarray(b, dtype=np.float32))
        width = w.shape[1]
    if width != len(PART_NAMES):
        raise ValueError(
            f"The last layer of BodyPartNet must give {len(PART_NAMES)} parts. Got {width}."
        )
    check_scalar(clip, "clip", low=0.0, caller="BodyPartNet")
    check_scalar(reference_focal, "reference_focal", low=0.0, caller="BodyPartNet")
    offsets = np.ascontiguousarray(offsets, dtype=np.float32)
    for array in (offsets, *checked_w, *checked_b):
        array.setflags(write=False)
    return offsets, tuple(checked_w), tuple(checked_b)


# --------------------------------------------------------------------------- kernels
def _forward(
    x: np.ndarray, weights: Sequence[np.ndarray], biases: Sequence[np.ndarray]
) -> np.ndarray:
    """The logits ``(N, D_out)`` of float32 inputs ``(N, K)``: ReLU between layers."""
    h = x
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        h = h @ w
        h += b
        if i < len(weights) - 1:
            np.maximum(h, 0.0, out=h)
    return h


def _softmax(logits: np.ndarray) -> np.ndarray:
    """Row-wise softmax, in place."""
    logits -= logits.max(axis=1, keepdims=True)
    np.exp(logits, out=logits)
    logits /= logits.sum(axis=1, keepdims=True)
    return logits


def fit_perceptron(
    x: np.ndarray,
    y: np.ndarray,
    *,
    hidden: Sequence[int] = (256, 256, 128),
    n_classes: int | None = None,
    clip: float = 1.0,
    epochs: int = 8,
    batch_size: int = 1024,
    learning_rate: float = 2e-3,
    weight_decay: float = 1e-4,
    label_smoothing: float = 0.05,
    rng: int | np.random.Generator | None = None,
    on_epoch: Callable[[int, float], None] | None = None,
) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
    """Train a ReLU perceptron by mini-batch AdamW on cross-entropy, in float32.

    The learning rate follows a one-cycle schedule: a linear rise over the first 30%
    of the steps to ``learning_rate``, then a cosine fall to nearly zero. Weight
    decay is decoupled (AdamW) and spares the biases.

    Parameters
    ----------
    x : (N, K) float
        Inputs (float16 is read a batch at a time), clipped to ``[-clip, clip]``.
    y : (N,) int
        Classes ``0 .. n_classes - 1``.
    hidden : sequence of int
        Widths of the hidden layers.
    n_classes : int, optional
        Default ``y.max() + 1``.
    epochs, batch_size, learning_rate, weight_decay, label_smoothing :
        The optimisation (label smoothing: the target puts ``label_smoothing`` of its
        mass uniformly over the classes).
    rng : int, Generator or None
        The initial weights and the order of the samples.
    on_epoch : callable, optional
        Called as ``on_epoch(epoch, mean_loss)`` after each epoch.

    Returns
    -------
    weights, biases : tuples of float32 arrays
        For :class:`BodyPartNet`.

    Examples
    --------
    Two classes split by the sign of the first input:

    >>> import numpy as np
    >>> x = np.random.default_rng(0).uniform(-1, 1, (2000, 4)).astype(np.float32)
    >>> w, b = fit_perceptron(x, (x[:, 0] > 0).astype(int), hidden=(16,), epochs=5, rng=0)
    >>> float(np.mean(np.argmax(_forward(x, w, b), axis=1) == (x[:, 0] > 0)))  # doctest: +SKIP
    0.99...
    """
    rng = check_rng(rng)
    y = np.asarray(y).astype(np.intp, copy=False)
    if x.ndim != 2 or len(x) != len(y) or len(x) == 0:
        raise ValueError(
            f"fit_perceptron needs a non-empty (N, K) 'x' and (N,) 'y'. "
            f"Got {x.shape} and {y.shape}."
        )
    n_classes = int(y.max()) + 1 if n_classes is None else int(n_classes)
    if y.min() < 0 or y.max() >= n_classes:
        raise ValueError(f"The classes 'y' of fit_perceptron must lie in [0, {n_classes}).")
    epochs = check_scalar(epochs, "epochs", low=1, include_low=True, integer=True)
    batch_size = check_scalar(batch_size, "batch_size", low=1, include_low=True, integer=True)
    dims = [x.shape[1], *[int(h) for h in hidden], n_classes]
    weights = [
        (rng.standard_normal((a, b)) * np.sqrt(2.0 / a)).astype(np.float32)
        for a, b in itertools.pairwise(dims)
    ]
    biases = [np.zeros(b, dtype=np.float32) for b in dims[1:]]
    params = [p for pair in zip(weights, biases, strict=True) for p in pair]
    moment1 = [np.zeros_like(p) for p in params]
    moment2 = [np.zeros_like(p) for p in params]
    beta1, beta2, eps = 0.9, 0.999, 1e-8
    n_batches = max(len(x) // batch_size, 1)
    total = epochs * n_batches
    smooth = np.float32(label_smoothing / n_classes)
    step = 0
    for epoch in range(epochs):
        order = rng.permutation(len(x))
        losses = []
        for k in range(n_batches):
            idx = np.sort(order[k * batch_size : (k + 1) * batch_size])  # sorted: faster reads
            xb = np.clip(x[idx], -clip, clip, dtype=np.float32)
            grads, loss = _gradients(xb, y[idx], weights, biases, label_smoothing, smooth)
            losses.append(loss)
            step += 1
            rate = _one_cycle(step, total, learning_rate)
            fix1, fix2 = 1.0 - beta1**step, 1.0 - beta2**step
            for j, (p, g) in enumerate(zip(params, grads, strict=True)):
                m, v = moment1[j], moment2[j]
                m *= beta1
                m += (1.0 - beta1) * g
                v *= beta2
                v += (1.0 - beta2) * (g * g)
                if j % 2 == 0:  # weights, not biases, decay
                    p *= np.float32(1.0 - rate * weight_decay)
                p -= np.float32(rate / fix1) * m / (np.sqrt(v / np.float32(fix2)) + eps)
        if on_epoch is not None:
            on_epoch(epoch, float(np.mean(losses)))
    return tuple(weights), tuple(biases)


def _one_cycle(step: int, total: int, peak: float) -> float:
    """Learning rate at ``step`` of ``total``: linear rise over 30%, cosine fall."""
    rise = max(int(0.3 * total), 1)
    if step <= rise:
        return peak * (0.04 + 0.96 * step / rise)
    t = (step - rise) / max(total - rise, 1)
    return peak * (1e-4 + (1.0 - 1e-4) * 0.5 * (1.0 + np.cos(np.pi * t)))


def _gradients(xb, yb, weights, biases, label_smoothing, smooth):
    """Cross-entropy (with label smoothing) of one batch and its gradients."""
    activations = [xb]
    h = xb
    for i, (w, b) in enumerate(zip(weights, biases, strict=True)):
        h = h @ w
        h += b
        if i < len(weights) - 1:
            np.maximum(h, 0.0, out=h)
            activations.append(h)
    logits = h
    logits -= logits.max(axis=1, keepdims=True)
    log_norm = np.log(np.exp(logits).sum(axis=1, keepdims=True))
    log_p = logits - log_norm
    rows = np.arange(len(yb))
    loss = -(1.0 - label_smoothing) * log_p[rows, yb].mean() - smooth * log_p.sum(axis=1).mean()
    delta = np.exp(log_p)
    delta -= smooth
    delta[rows, yb] -= np.float32(1.0 - label_smoothing)
    delta /= np.float32(len(yb))
    grads: list[np.ndarray] = []
    for i in range(len(weights) - 1, -1, -1):
        grads.append(delta.sum(axis=0))
        grads.append(activations[i].T @ delta)
        if i:
            delta = delta @ weights[i].T
            delta *= activations[i] > 0
    grads.reverse()  # (dW0, db0, dW1, db1, ...)
    return grads, float(loss)
