"""The body-part forest: a per-pixel random forest over depth-comparison features.

The model is plain arrays (no pickled objects): split feature ids into a bank of
offset pairs, float32 thresholds, int32 children and per-leaf part distributions.
Inference classifies every foreground pixel of a frame together, level by level:
each pixel computes only the one feature its current node asks for.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from os import PathLike
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from posedrift.camera import Intrinsics
from posedrift.labelling._features import (
    BACKGROUND_DEPTH,
    REFERENCE_FOCAL,
    CheckedPixels,
    checked_frame,
    foreground_pixels,
    pixel_terms,
    probe,
    probe_image,
)
from posedrift.labelling._modelfile import (
    check_header,
    float_scalars,
    open_archive,
    read_model_file,
    read_packaged_model,
)
from posedrift.labelling._votes import JointVotes
from posedrift.skeleton import PART_NAMES

try:  # the compiled kernels are optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.labelling import _ckernels  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _ckernels = None

FORMAT_NAME = "posedrift-body-part-forest"
FORMAT_VERSION = 1
MAX_DEPTH = 64
"""Deepest tree a model file may hold (bounds the level-by-level loop)."""
MAX_OFFSET = 5000.0
"""Largest offset (pixel x metres) a model file may hold."""

_DEFAULT_MODEL = "forest_default.npz"
_FUSED_PAIRS = 6000  # (tree, pixel) pairs up to which the fused descent is faster
_LOADED_DEFAULT: list = []  # the default model, once loaded
_KEYS = (
    "format",
    "version",
    "part_names",
    "metadata",
    "reference_focal",
    "background",
    "offsets",
    "roots",
    "feature",
    "threshold",
    "left",
    "right",
    "leaf",
    "leaf_values",
)
_VOTE_KEYS = ("vote_joint", "vote_offset", "vote_weight", "vote_radius")
"""Optional arrays of a model with joint votes (:class:`JointVotes`)."""


@dataclass(frozen=True)
class PartPrediction:
    """Per-pixel body-part labels of one frame.

    Parameters
    ----------
    labels : (H, W) int16
        Part index (``skeleton.PART_NAMES`` order) of each foreground pixel, -1 elsewhere.
    pixels : (N, 2) intp
        ``(row, column)`` of the classified pixels, row-major order.
    probabilities : (N, 15) float32
        ``P(part | pixel)``, averaged over the trees; each row sums to 1.
    """

    labels: np.ndarray
    pixels: np.ndarray
    probabilities: np.ndarray


@dataclass(frozen=True, eq=False)
class BodyPartForest:
    """A random forest that labels depth pixels with the 15 body parts.

    Nodes of all trees share one set of arrays; ``roots[t]`` is tree ``t``'s root.
    An internal node ``i`` sends a pixel to ``left[i]`` when its feature
    ``offsets[feature[i]]`` is ``<= threshold[i]``, else to ``right[i]``; a leaf has
    ``feature == left == right == -1`` and its distribution in ``leaf_values[leaf[i]]``.

    Parameters
    ----------
    offsets : (K, 4) float32
        Offset pairs ``(u_row, u_col, v_row, v_col)`` in pixel x metres at ``reference_focal``.
    roots : (T,) int32
    feature, left, right, leaf : (M,) int32
    threshold : (M,) float32
        Depth differences in metres.
    leaf_values : (L, 15) float32
        Part distributions of the leaves (rows sum to 1).
    reference_focal : float
        Focal length (pixels) of the offsets.
    background : float
        Depth (metres) read by background and off-image probes.
    metadata : mapping
        JSON-serialisable facts about training (seed, frames, ...); read-only.
    votes : JointVotes, optional
        Where each leaf's training pixels saw the joints (:meth:`with_votes`);
        ``None`` for a model that only labels.

    Examples
    --------
    >>> forest = BodyPartForest.load_default()
    >>> forest.n_trees, forest.n_parts
    (3, 15)
    """

    offsets: np.ndarray
    roots: np.ndarray
    feature: np.ndarray
    threshold: np.ndarray
    left: np.ndarray
    right: np.ndarray
    leaf: np.ndarray
    leaf_values: np.ndarray
    reference_focal: float = REFERENCE_FOCAL
    background: float = BACKGROUND_DEPTH
    metadata: Mapping[str, Any] = field(default_factory=dict)
    votes: JointVotes | None = None

    def __post_init__(self) -> None:
        arrays = _validate_arrays(
            {
                "offsets": self.offsets,
                "roots": self.roots,
                "feature": self.feature,
                "threshold": self.threshold,
                "left": self.left,
                "right": self.right,
                "leaf": self.leaf,
                "leaf_values": self.leaf_values,
            },
            float(self.reference_focal),
            float(self.background),
            "BodyPartForest",
        )
        depth = arrays.pop("depth")
        for name, value in arrays.items():
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "_depth", int(depth))
        object.__setattr__(self, "_table", _node_table(arrays))
        object.__setattr__(self, "reference_focal", float(self.reference_focal))
        object.__setattr__(self, "background", float(self.background))
        object.__setattr__(self, "metadata", MappingProxyType(dict(self.metadata)))
        if self.votes is not None:
            if not isinstance(self.votes, JointVotes):
                raise ValueError(
                    f"The 'votes' of BodyPartForest must be JointVotes or None. "
                    f"Got {type(self.votes).__name__} instead."
                )
            if self.votes.n_leaves != len(self.leaf_values):
                raise ValueError(
                    f"The 'votes' of BodyPartForest must have one row per leaf "
                    f"({len(self.leaf_values)}). Got {self.votes.n_leaves}."
                )

    # ------------------------------------------------------------------ properties
    @property
    def n_trees(self) -> int:
        """Number of trees."""
        return len(self.roots)

    @property
    def n_parts(self) -> int:
        """Number of body parts (15)."""
        return self.leaf_values.shape[1]

    @property
    def depth(self) -> int:
        """Depth of the deepest tree (edges from the root to the deepest leaf)."""
        return self._depth

    @property
    def n_nodes(self) -> int:
        """Number of nodes over all trees."""
        return len(self.feature)

    # ------------------------------------------------------------------ building
    @classmethod
    def from_sklearn(
        cls,
        estimator: Any,
        offsets: np.ndarray,
        *,
        reference_focal: float = REFERENCE_FOCAL,
        background: float = BACKGROUND_DEPTH,
        metadata: dict | None = None,
    ) -> BodyPartForest:
        """Export a fitted scikit-learn forest (or single tree) to arrays.

        Parameters
        ----------
        estimator : RandomForestClassifier, ExtraTreesClassifier or DecisionTreeClassifier
            Fitted on a feature matrix whose column ``k`` is offset pair ``offsets[k]``
            and whose classes are part indices in ``0..14``.
        offsets : (K, 4) float
            The offset bank, in the columns' order.

        Returns
        -------
        BodyPartForest
            Routes every feature vector to the same leaves as ``estimator`` does;
            its probabilities equal ``estimator.predict_proba`` up to float32 rounding.
        """
        if not hasattr(estimator, "classes_"):
            raise ValueError("The 'estimator' of BodyPartForest.from_sklearn must be fitted.")
        trees = getattr(estimator, "estimators_", [estimator])
        classes = np.asarray(estimator.classes_)
        n_parts = len(PART_NAMES)
        if (
            not np.issubdtype(classes.dtype, np.integer)
            or classes.min() < 0
            or classes.max() >= n_parts
        ):
            raise ValueError(
                f"The 'estimator' of BodyPartForest.from_sklearn must be fitted on part "
                f"indices 0..{n_parts - 1}. Got classes {classes.tolist()}."
            )
        offsets = np.asarray(offsets, dtype=np.float32)
        roots, features, thresholds, lefts, rights, leaves, values = [], [], [], [], [], [], []
        base = 0
        n_leaves = 0
        for tree in trees:
            t = tree.tree_
            left = t.children_left.astype(np.int64)
            right = t.children_right.astype(np.int64)
            is_leaf = left < 0
            feature = np.where(is_leaf, -1, t.feature).astype(np.int32)
            threshold = np.where(is_leaf, 0.0, t.threshold)
            value = t.value[:, 0, :].astype(np.float64)
            leaf = np.full(t.node_count, -1, dtype=np.int64)
            leaf[is_leaf] = n_leaves + np.arange(np.count_nonzero(is_leaf))
            dist = np.zeros((np.count_nonzero(is_leaf), n_parts))
            dist[:, classes] = value[is_leaf]
            dist /= dist.sum(axis=1, keepdims=True)
            roots.append(base)
            features.append(feature)
            thresholds.append(_floor_float32(threshold))
            lefts.append(np.where(is_leaf, -1, left + base))
            rights.append(np.where(is_leaf, -1, right + base))
            leaves.append(leaf)
            values.append(dist)
            base += t.node_count
            n_leaves += len(dist)
        if offsets.ndim != 2 or int(max(f.max() for f in features)) >= len(offsets):
            raise ValueError(
                f"The 'offsets' of BodyPartForest.from_sklearn must have a row per feature "
                f"column of the estimator. Got shape {offsets.shape}."
            )
        return cls(
            offsets=offsets,
            roots=np.asarray(roots, dtype=np.int32),
            feature=np.concatenate(features).astype(np.int32),
            threshold=np.concatenate(thresholds),
            left=np.concatenate(lefts).astype(np.int32),
            right=np.concatenate(rights).astype(np.int32),
            leaf=np.concatenate(leaves).astype(np.int32),
            leaf_values=np.concatenate(values).astype(np.float32),
            reference_focal=reference_focal,
            background=background,
            metadata=metadata or {},
        )

    # ------------------------------------------------------------------ files
    def save(self, path: str | PathLike) -> Path:
        """Write the model to ``path`` (a compressed ``.npz`` of plain arrays).

        Leaf distributions are stored as float16, joint votes quantized
        (:meth:`_vote_arrays`); nothing is pickled.
        """
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        with open(path, "wb") as handle:
            np.savez_compressed(
                handle,
                format=np.array(FORMAT_NAME),
                version=np.array(FORMAT_VERSION, dtype=np.int32),
                part_names=np.array(PART_NAMES),
                metadata=np.array(json.dumps(dict(self.metadata), sort_keys=True)),
                reference_focal=np.array(self.reference_focal),
                background=np.array(self.background),
                offsets=self.offsets,
                roots=self.roots,
                feature=self.feature,
                threshold=self.threshold,
                left=self.left,
                right=self.right,
                leaf=self.leaf,
                leaf_values=self.leaf_values.astype(np.float16),
                **self._vote_arrays(),
            )
        return path

    def _vote_arrays(self) -> dict[str, np.ndarray]:
        """The votes as stored, or nothing: offsets as int8 steps of ``radius / 127``
        (1.6 mm at 0.2 m; no offset component exceeds the radius) and weights as
        uint8 steps of 1/255, which keeps the shipped model small."""
        if self.votes is None:
            return {}
        votes = self.votes
        step = votes.radius / 127.0
        return {
            "vote_joint": votes.joint,
            "vote_offset": np.clip(np.rint(votes.offset / step), -127, 127).astype(np.int8),
            "vote_weight": np.rint(votes.weight * 255.0).astype(np.uint8),
            "vote_radius": np.array(votes.radius),
        }

    def with_votes(self, votes: JointVotes | None) -> BodyPartForest:
        """The same trees with ``votes`` (:func:`~posedrift.labelling.fit_joint_votes`)."""
        return replace(self, votes=votes)

    @classmethod
    def load(cls, path: str | PathLike) -> BodyPartForest:
        """Read a model written by :meth:`save`, checking every array; never unpickles.

        Raises
        ------
        ValueError
            If the file is not a posedrift forest, has another format version, is
            truncated or corrupt, or holds arrays of the wrong shape, dtype or range
            (children or feature ids out of range, cycles, non-finite values).
        """
        return cls._from_bytes(read_model_file(path, "forest model"), str(Path(path)))

    @classmethod
    def load_default(cls) -> BodyPartForest:
        """The model shipped with posedrift (trained by ``posedrift train``).

        Loaded once per process and shared: the model is immutable.
        """
        if not _LOADED_DEFAULT:
            data = read_packaged_model(_DEFAULT_MODEL, "forest model", "posedrift train")
            _LOADED_DEFAULT.append(cls._from_bytes(data, f"posedrift/data/{_DEFAULT_MODEL}"))
        return _LOADED_DEFAULT[0]

    @classmethod
    def _from_bytes(cls, data: bytes, where: str) -> BodyPartForest:
        prefix = f"The forest model file {where}"
        arrays = open_archive(data, prefix)
        metadata = check_header(
            arrays,
            prefix,
            kind="forest",
            format_name=FORMAT_NAME,
            version=FORMAT_VERSION,
            command="posedrift train",
            required=_KEYS[2:],
        )
        stored = [k for k in _VOTE_KEYS if k in arrays]
        if stored and len(stored) != len(_VOTE_KEYS):
            raise ValueError(
                f"{prefix} has incomplete joint votes: "
                f"missing {sorted(set(_VOTE_KEYS) - set(stored))}."
            )
        vote_arrays = {k: arrays[k] for k in stored}
        scalars = float_scalars(arrays, ("reference_focal", "background"), prefix)
        leaf_values = arrays["leaf_values"]
        if leaf_values.dtype not in (np.float16, np.float32):
            raise ValueError(
                f"{prefix} has 'leaf_values' of dtype {leaf_values.dtype}; expected float16/32."
            )
        arrays["leaf_values"] = leaf_values.astype(np.float32)
        try:
            votes = None
            if vote_arrays:
                kinds = {k: vote_arrays[k].dtype for k in _VOTE_KEYS}
                if (kinds["vote_joint"], kinds["vote_offset"], kinds["vote_weight"]) != (
                    np.int8,
                    np.int8,
                    np.uint8,
                ) or kinds["vote_radius"].kind != "f":
                    raise ValueError(f"its joint votes have unexpected dtypes {kinds}")
                radius = float(vote_arrays["vote_radius"])
                votes = JointVotes(
                    joint=vote_arrays["vote_joint"],
                    offset=vote_arrays["vote_offset"] * np.float32(radius / 127.0),
                    weight=vote_arrays["vote_weight"] / np.float32(255.0),
                    radius=radius,
                )
            return cls(
                **{k: arrays[k] for k in _KEYS[6:]},
                reference_focal=scalars["reference_focal"],
                background=scalars["background"],
                metadata=metadata,
                votes=votes,
            )
        except ValueError as exc:
            raise ValueError(f"{prefix} is invalid: {exc}") from exc

    # ------------------------------------------------------------------ inference
    def predict(
        self, depth: np.ndarray, mask: np.ndarray | None, intrinsics: Intrinsics
    ) -> PartPrediction:
        """Label every foreground pixel of a depth frame with a body part.

        Parameters
        ----------
        depth : (H, W) float
            Depth in metres (0 or NaN: no measurement).
        mask : (H, W) bool or None
            The person's pixels (the tracker's segmentation); ``None`` takes every
            pixel with depth. Pixels without depth are never labelled.
        intrinsics : Intrinsics
            The camera; offsets scale by its focal length over ``reference_focal``.

        Returns
        -------
        PartPrediction
            An all ``-1`` label map and empty arrays when there is no foreground.

        Examples
        --------
        >>> import numpy as np
        >>> from posedrift.camera import camera_preset
        >>> cam = camera_preset("kinect1-qvga")
        >>> pred = BodyPartForest.load_default().predict(np.zeros((240, 320)), None, cam)
        >>> pred.labels.shape, pred.probabilities.shape
        ((240, 320), (0, 15))
        """
        depth, valid = checked_frame(depth, mask, intrinsics, "BodyPartForest.predict")
        flat, pixels = foreground_pixels(valid)
        labels = np.full(depth.shape, -1, dtype=np.int16)
        if len(pixels) == 0:
            return PartPrediction(
                labels=labels,
                pixels=pixels,
                probabilities=np.zeros((0, self.n_parts), dtype=np.float32),
            )
        image = probe_image(depth, valid, self.background)
        terms = pixel_terms(depth, pixels, intrinsics, self.reference_focal)
        reached = self._descend_frame(image, depth.shape, terms)
        probabilities = self._average_leaves(reached)
        np.put(labels, flat, _argmax_rows(probabilities))
        return PartPrediction(labels=labels, pixels=pixels, probabilities=probabilities)

    def predict_pixels(
        self,
        depth: np.ndarray,
        pixels: np.ndarray,
        intrinsics: Intrinsics,
        *,
        mask: np.ndarray | None = None,
        return_leaves: bool = False,
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """Part probabilities of only the given pixels (cheap per-point appearance).

        The probes read the same image as :meth:`predict` (background outside
        ``mask`` and where depth is missing), so each row equals that pixel's row
        of ``predict(depth, mask, intrinsics).probabilities``.

        Parameters
        ----------
        depth : (H, W) float
            Depth in metres.
        pixels : (N, 2) int
            ``(row, column)`` of the pixels to classify.
        intrinsics : Intrinsics
        mask : (H, W) bool, optional
            The person's pixels; ``None`` takes every pixel with depth.
        return_leaves : bool
            Also return the leaf rows reached (for :attr:`votes`).

        Returns
        -------
        (N, 15) float32
            ``P(part | pixel)``; a uniform row for a pixel outside the foreground.
        leaves : (T, N) int32
            Only with ``return_leaves``: the row of ``leaf_values`` each pixel reached
            in each tree; -1 for a pixel outside the foreground.

        Examples
        --------
        >>> import numpy as np
        >>> from posedrift.camera import camera_preset
        >>> cam = camera_preset("kinect1-qvga")
        >>> depth = np.zeros(cam.shape, np.float32); depth[100:140, 150:170] = 2.5
        >>> forest = BodyPartForest.load_default()
        >>> forest.predict_pixels(depth, np.array([[120, 160], [0, 0]]), cam).shape
        (2, 15)
        """
        checked = CheckedPixels(depth, mask, pixels, intrinsics, "BodyPartForest.predict_pixels")
        return self._predict_checked(checked, return_leaves=return_leaves)

    def _predict_checked(
        self, checked: CheckedPixels, *, return_leaves: bool = False
    ) -> np.ndarray | tuple[np.ndarray, np.ndarray]:
        """:meth:`predict_pixels` of :class:`CheckedPixels` (checks and probes shared)."""
        n = len(checked.pixels)
        out = np.full((n, self.n_parts), 1.0 / self.n_parts, dtype=np.float32)
        leaves = np.full((self.n_trees, n), -1, dtype=np.int32)
        inside = checked.inside
        if inside.any():
            image = checked.image(self.background)
            terms = checked.terms(self.reference_focal)
            reached = self._descend_frame(image, checked.depth.shape, terms)
            out[inside] = self._average_leaves(reached)
            leaves[:, inside] = np.take(self.leaf, reached)
        return (out, leaves) if return_leaves else out

    def _descend_frame(
        self, image: np.ndarray, shape: tuple[int, int], terms: tuple[np.ndarray, ...]
    ) -> np.ndarray:
        """Every (tree, pixel) pair down its tree, all together, one level per step.

        Leaves loop onto themselves (offsets 0, threshold +inf), so the arrays never
        shrink: each step is a fixed handful of whole-array operations.
        Returns ``(T, N)`` leaf node ids.
        """
        if _ckernels is not None:
            return self._descend_compiled(image, shape, terms)
        if len(terms[0]) * self.n_trees <= _FUSED_PAIRS:
            return self._descend_fused(image, shape, terms)
        n = len(terms[0])
        n_trees = self.n_trees
        tiled = tuple(np.tile(t, n_trees) for t in terms)
        node = np.repeat(self.roots.astype(np.intp), n)
        table = self._table
        for _ in range(self._depth):
            # One 32-byte row gather per pair; 1-D strided columns keep the loops fast.
            record = np.take(table, node, axis=0).view(np.int32)
            values = record.view(np.float32)
            feature = probe(image, shape, *tiled, values[:, 0], values[:, 1])
            feature -= probe(image, shape, *tiled, values[:, 2], values[:, 3])
            node = np.where(feature <= values[:, 4], record[:, 5], record[:, 6])
        return node.reshape(n_trees, n)

    def _descend_compiled(
        self, image: np.ndarray, shape: tuple[int, int], terms: tuple[np.ndarray, ...]
    ) -> np.ndarray:
        """:meth:`_descend_frame` by the compiled kernel (``_ckernels.c``): the same leaves."""
        out = np.empty((self.n_trees, len(terms[0])), dtype=np.int32)
        _ckernels.descend(
            self._table.view(np.int32),
            np.ascontiguousarray(image, dtype=np.float32),
            *(np.ascontiguousarray(t, dtype=np.float32) for t in terms),
            np.ascontiguousarray(self.roots, dtype=np.int32),
            self._depth,
            shape[0],
            shape[1],
            out,
        )
        return out

    def _descend_fused(
        self, image: np.ndarray, shape: tuple[int, int], terms: tuple[np.ndarray, ...]
    ) -> np.ndarray:
        """:meth:`_descend_frame` for few pairs (the tracker's per-point evidence).

        Both probes of a pair are computed together, as rows ``(u_row, v_row, u_col,
        v_col)`` of ``(4, pairs)`` arrays, with the same float32 operations in the same
        order as :func:`posedrift.labelling._features.probe` (so the same leaves): half
        the array operations per level, which dominate at a few hundred pixels.
        """
        n = len(terms[0])
        n_trees = self.n_trees
        height, width = shape
        rows, cols, row_scale, col_scale = (np.tile(t, n_trees) for t in terms)
        # Both probes of a pair at once, as rows (u_row, v_row, u_col, v_col) of (4, pairs)
        # arrays: the same float32 operations, in the same order, as features.probe.
        scale = np.stack([row_scale, row_scale, col_scale, col_scale])
        base = np.stack([rows, rows, cols, cols])
        lower = np.zeros((4, 1), dtype=np.float32)
        upper = np.array([[height + 1], [height + 1], [width + 1], [width + 1]], np.float32)
        stride = np.int32(width + 2)
        at = np.empty_like(scale)
        index = np.empty(scale.shape, dtype=np.int32)
        node = np.repeat(self.roots.astype(np.intp), n)
        table = self._table
        for _ in range(self._depth):
            # One 32-byte row gather per pair; then whole-array operations.
            record = np.take(table, node, axis=0).view(np.int32)
            values = record.view(np.float32)
            np.multiply(values[:, [0, 2, 1, 3]].T, scale, out=at)
            at += base
            np.maximum(at, lower, out=at)
            np.minimum(at, upper, out=at)
            index[...] = at  # truncation, as astype(np.int32)
            flat = index[:2] * stride
            flat += index[2:]
            depth = np.take(image, flat)
            feature = depth[0] - depth[1]
            node = np.where(feature <= values[:, 4], record[:, 5], record[:, 6])
        return node.reshape(n_trees, n)

    def predict_proba_features(self, features: np.ndarray) -> np.ndarray:
        """Part probabilities ``(N, 15)`` float32 from a precomputed feature matrix.

        Parameters
        ----------
        features : (N, K) float
            Column ``k`` is offset pair ``k`` (as in training).
        """
        x = np.asarray(features, dtype=np.float32)
        if x.ndim != 2 or x.shape[1] != len(self.offsets):
            raise ValueError(
                f"The 'features' argument must be an (N, {len(self.offsets)}) matrix. "
                f"Got shape {x.shape} instead."
            )
        return self._average_leaves(self._leaves(len(x), lambda active, ids: x[active, ids]))

    def apply_features(self, features: np.ndarray) -> np.ndarray:
        """Leaf node reached in each tree, ``(N, T)`` int32 (global node ids)."""
        x = np.asarray(features, dtype=np.float32)
        return self._leaves(len(x), lambda active, ids: x[active, ids]).T.copy()

    def _leaves(self, n: int, features: Any) -> np.ndarray:
        """Level-by-level descent of ``n`` samples through every tree: ``(T, n)`` leaf ids."""
        n_trees = self.n_trees
        reached = np.empty(n_trees * n, dtype=np.int32)
        slot = np.arange(n_trees * n, dtype=np.intp)
        sample = np.tile(np.arange(n, dtype=np.intp), n_trees)
        node = np.repeat(self.roots.astype(np.intp), n)
        for _ in range(MAX_DEPTH + 1):
            ids = self.feature[node]
            at_leaf = ids < 0
            if at_leaf.any():
                reached[slot[at_leaf]] = node[at_leaf]
                keep = ~at_leaf
                slot, sample, node, ids = slot[keep], sample[keep], node[keep], ids[keep]
            if len(node) == 0:
                break
            go_left = features(sample, ids) <= self.threshold[node]
            node = np.where(go_left, self.left[node], self.right[node])
        return reached.reshape(n_trees, n)

    def _average_leaves(self, reached: np.ndarray) -> np.ndarray:
        """Mean leaf distribution over the trees, ``(N, 15)`` float32."""
        total = np.take(self.leaf_values, np.take(self.leaf, reached[0]), axis=0)
        for t in range(1, self.n_trees):
            total += np.take(self.leaf_values, np.take(self.leaf, reached[t]), axis=0)
        total /= np.float32(self.n_trees)
        return total


def _argmax_rows(values: np.ndarray) -> np.ndarray:
    """``values.argmax(axis=1)`` (first maximum wins), fast for few columns."""
    best = values[:, 0].copy()
    index = np.zeros(len(values), dtype=np.int16)
    for k in range(1, values.shape[1]):
        column = values[:, k]
        better = column > best
        index[better] = k
        np.maximum(best, column, out=best)
    return index


def _node_table(arrays: dict[str, np.ndarray]) -> np.ndarray:
    """Per node, one 32-byte record read with one gather per level during inference.

    As int32 columns: ``u_row, u_col, v_row, v_col, threshold`` (float32 bits),
    ``left``, ``right``, spare; returned as an ``(M, 4)`` int64 view (fast row gathers).
    A leaf points to itself on both sides with zero offsets and an infinite threshold.
    """
    feature = arrays["feature"]
    n = len(feature)
    internal = feature >= 0
    index = np.arange(n, dtype=np.int32)
    values = np.zeros((n, 8), dtype=np.float32)
    values[internal, :4] = arrays["offsets"][feature[internal]]
    values[:, 4] = np.where(internal, arrays["threshold"], np.float32(np.inf))
    table = values.view(np.int32)
    table[:, 5] = np.where(internal, arrays["left"], index)
    table[:, 6] = np.where(internal, arrays["right"], index)
    table = table.view(np.int64)
    table.setflags(write=False)
    return table


def _floor_float32(threshold: np.ndarray) -> np.ndarray:
    """Largest float32 ``<= threshold``: ``x <= t`` then holds for float32 ``x`` exactly."""
    t32 = threshold.astype(np.float32)
    above = t32.astype(np.float64) > threshold
    t32[above] = np.nextafter(t32[above], np.float32(-np.inf))
    return t32


def _validate_arrays(
    arrays: dict[str, Any], reference_focal: float, background: float, caller: str
) -> dict[str, np.ndarray]:
    """Check dtypes, shapes, ranges and the tree structure; return contiguous copies."""

    def typed(name: str, kinds: str, ndim: int) -> np.ndarray:
        value = np.asarray(arrays[name])
        if value.dtype.kind not in kinds or value.ndim != ndim:
            raise ValueError(
                f"The '{name}' array of {caller} must be a {ndim}-D "
                f"{'integer' if kinds == 'iu' else 'float'} array. "
                f"Got dtype {value.dtype}, shape {value.shape}."
            )
        return value

    if not (np.isfinite(reference_focal) and reference_focal > 0):
        raise ValueError(
            f"The 'reference_focal' of {caller} must be a positive focal length in pixels. "
            f"Got {reference_focal!r}."
        )
    if not (np.isfinite(background) and background > 0):
        raise ValueError(
            f"The 'background' of {caller} must be a positive depth in metres. Got {background!r}."
        )
    offsets = typed("offsets", "f", 2)
    if offsets.shape[1] != 4 or len(offsets) == 0:
        raise ValueError(f"The 'offsets' array of {caller} must be (K, 4). Got {offsets.shape}.")
    if not np.all(np.isfinite(offsets)) or np.abs(offsets).max() > MAX_OFFSET:
        raise ValueError(
            f"The 'offsets' array of {caller} must be finite and within +-{MAX_OFFSET:g} "
            f"pixel x metres."
        )
    roots = typed("roots", "iu", 1)
    feature = typed("feature", "iu", 1)
    threshold = typed("threshold", "f", 1)
    left = typed("left", "iu", 1)
    right = typed("right", "iu", 1)
    leaf = typed("leaf", "iu", 1)
    leaf_values = typed("leaf_values", "f", 2)
    n_nodes = len(feature)
    for name, value in (("threshold", threshold), ("left", left), ("right", right), ("leaf", leaf)):
        if len(value) != n_nodes:
            raise ValueError(
                f"The '{name}' array of {caller} must have one entry per node ({n_nodes}). "
                f"Got {len(value)}."
            )
    if n_nodes == 0 or len(roots) == 0:
        raise ValueError(f"A {caller} needs at least one tree. Got {len(roots)} roots.")
    if leaf_values.shape[1] != len(PART_NAMES) or len(leaf_values) == 0:
        raise ValueError(
            f"The 'leaf_values' array of {caller} must be (L, {len(PART_NAMES)}). "
            f"Got {leaf_values.shape}."
        )
    if (
        not np.all(np.isfinite(leaf_values))
        or leaf_values.min() < 0
        or not np.allclose(leaf_values.sum(axis=1), 1.0, atol=1e-2)
    ):
        raise ValueError(
            f"The 'leaf_values' of {caller} must be probability distributions (finite, "
            f"non-negative, rows summing to 1)."
        )
    if not np.all(np.isfinite(threshold)):
        raise ValueError(f"The 'threshold' array of {caller} must be finite.")
    if roots.min() < 0 or roots.max() >= n_nodes:
        raise ValueError(f"The 'roots' of {caller} must index nodes in [0, {n_nodes}).")
    is_leaf = feature < 0
    index = np.arange(n_nodes)
    if np.any(feature >= len(offsets)) or np.any(feature < -1):
        raise ValueError(
            f"The 'feature' ids of {caller} must be -1 (leaf) or in [0, {len(offsets)})."
        )
    internal = ~is_leaf
    if np.any(left[is_leaf] != -1) or np.any(right[is_leaf] != -1):
        raise ValueError(f"The leaves of {caller} must have children -1.")
    for name, child in (("left", left), ("right", right)):
        c = child[internal].astype(np.int64)
        if np.any(c <= index[internal]) or np.any(c >= n_nodes):
            raise ValueError(
                f"The '{name}' child indices of {caller} must lie in (node, {n_nodes}) "
                f"(children after their parent; no cycles)."
            )
    if (
        np.any(leaf[internal] != -1)
        or np.any(leaf[is_leaf] < 0)
        or (np.any(leaf[is_leaf] >= len(leaf_values)))
    ):
        raise ValueError(
            f"The 'leaf' indices of {caller} must be -1 for internal nodes and in "
            f"[0, {len(leaf_values)}) for leaves."
        )
    frontier = np.unique(roots.astype(np.int64))
    depth = 0
    for level in range(MAX_DEPTH + 1):
        depth = level
        frontier = frontier[internal[frontier]]
        if len(frontier) == 0:
            break
        frontier = np.unique(np.concatenate([left[frontier], right[frontier]]).astype(np.int64))
    else:
        raise ValueError(f"The trees of {caller} are deeper than {MAX_DEPTH} levels.")
    return {
        "offsets": np.ascontiguousarray(offsets, dtype=np.float32),
        "roots": np.ascontiguousarray(roots, dtype=np.int32),
        "feature": np.ascontiguousarray(feature, dtype=np.int32),
        "threshold": np.ascontiguousarray(threshold, dtype=np.float32),
        "left": np.ascontiguousarray(left, dtype=np.int32),
        "right": np.ascontiguousarray(right, dtype=np.int32),
        "leaf": np.ascontiguousarray(leaf, dtype=np.int32),
        "leaf_values": np.ascontiguousarray(leaf_values, dtype=np.float32),
        "depth": depth,
    }
