"""Joint votes at the forest's leaves (Girshick et al., ICCV 2011, beyond the paper).

Each leaf of the body-part forest also stores where the joints near its training
pixels were: for up to ``K`` joints, the mean offset from pixel to joint (camera
frame, metres) over the training pixels within ``radius`` of that joint, and the
share of the leaf's pixels that were. At run time every pixel casts one vote per
stored joint (its 3-D point plus the offset, weighted by the share), and a joint is
the mode of its votes nearest a starting guess.

The part labels say which part a pixel is on; the votes say where the joints are,
so a pixel on the wrong side of a part boundary still votes for the right place.
Trained on fresh renders, after the trees, without changing them.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass

import numpy as np

from posedrift._validation import check_rng, check_scalar
from posedrift.skeleton import JOINT_NAMES
from posedrift.skeleton._meanshift import _shift_modes

try:  # the compiled kernel is optional: the NumPy path casts the same votes
    from posedrift.labelling import _ckernels  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _ckernels = None

N_JOINTS = len(JOINT_NAMES)


@dataclass(frozen=True)
class JointVotes:
    """Per-leaf joint offsets of a :class:`~posedrift.labelling.BodyPartForest`.

    Parameters
    ----------
    joint : (L, K) int8
        Joint index (``JOINT_NAMES``) of each of a leaf's ``K`` votes; -1 for none.
    offset : (L, K, 3) float32
        Mean offset from a pixel's 3-D point to the joint, camera frame, metres.
    weight : (L, K) float32
        Share of the leaf's training pixels that lay within ``radius`` of the joint,
        in [0, 1]; 0 for no vote.
    radius : float
        Training pixels farther than this from a joint did not vote for it (metres).

    Examples
    --------
    >>> import numpy as np
    >>> votes = JointVotes(
    ...     joint=np.array([[8, -1]], np.int8),
    ...     offset=np.array([[[0.0, 0.0, 0.1], [0.0, 0.0, 0.0]]], np.float32),
    ...     weight=np.array([[0.5, 0.0]], np.float32),
    ...     radius=0.2,
    ... )
    >>> where, joint, weight = votes.cast(np.array([[0.0, 0.0, 2.0]]), np.array([[0]]))
    >>> np.round(where, 6).tolist(), joint.tolist(), weight.tolist()
    ([[0.0, 0.0, 2.1]], [8], [0.5])
    """

    joint: np.ndarray
    offset: np.ndarray
    weight: np.ndarray
    radius: float

    def __post_init__(self) -> None:
        caller = "JointVotes"
        joint = np.ascontiguousarray(self.joint, dtype=np.int8)
        offset = np.ascontiguousarray(self.offset, dtype=np.float32)
        weight = np.ascontiguousarray(self.weight, dtype=np.float32)
        if joint.ndim != 2 or weight.shape != joint.shape or offset.shape != (*joint.shape, 3):
            raise ValueError(
                f"The arrays of {caller} must be joint (L, K), offset (L, K, 3) and weight "
                f"(L, K). Got {joint.shape}, {offset.shape} and {weight.shape}."
            )
        if joint.size and (joint.min() < -1 or joint.max() >= N_JOINTS):
            raise ValueError(
                f"The 'joint' array of {caller} must hold joint indices 0..{N_JOINTS - 1} "
                f"or -1. Got {joint.min()}..{joint.max()}."
            )
        if not (np.isfinite(offset).all() and np.isfinite(weight).all()):
            raise ValueError(f"The 'offset' and 'weight' arrays of {caller} must be finite.")
        if weight.size and (weight.min() < 0 or weight.max() > 1):
            raise ValueError(f"The 'weight' array of {caller} must lie in [0, 1].")
        radius = check_scalar(self.radius, "radius", low=0.0, caller=caller)
        # A mean of offsets shorter than the radius: no component can exceed it (the
        # model file stores them in steps of radius / 127).
        if offset.size and np.abs(offset).max() > radius * (1 + 1e-5):
            raise ValueError(
                f"The 'offset' array of {caller} must lie within the radius ({radius:g} m) "
                f"in each component. Got {np.abs(offset).max():g}."
            )
        for name, value in (("joint", joint), ("offset", offset), ("weight", weight)):
            value.setflags(write=False)
            object.__setattr__(self, name, value)
        object.__setattr__(self, "radius", float(radius))

    @property
    def n_leaves(self) -> int:
        """Number of leaves (rows)."""
        return len(self.joint)

    def cast(
        self, points: np.ndarray, leaves: np.ndarray, *, joints=None, compiled: bool = True
    ) -> tuple[np.ndarray, ...]:
        """Every pixel's votes.

        Parameters
        ----------
        points : (N, 3) float
            The pixels' camera-frame points, metres.
        leaves : (T, N) int
            The leaf row each pixel reached in each tree; -1 for none.
        joints : sequence of int, optional
            Only the votes for these joints (indices). Default all.
        compiled : bool
            Use the compiled kernel where it is built (the same votes); False forces
            the NumPy path.

        Returns
        -------
        where : (M, 3) float
            Voted joint positions, metres.
        joint : (M,) int
            Joint of each vote.
        weight : (M,) float
            Each vote's weight (the tree's share, divided by the number of trees).
        """
        points = np.ascontiguousarray(points, dtype=np.float64)
        leaves = np.asarray(leaves)
        if points.ndim != 2 or points.shape[1] != 3 or leaves.ndim != 2:
            raise ValueError(
                "The arguments of JointVotes.cast must be points (N, 3) and leaves (T, N). "
                f"Got {points.shape} and {leaves.shape}."
            )
        if leaves.shape[1] != len(points) or (leaves.size and leaves.max() >= self.n_leaves):
            raise ValueError(
                f"The 'leaves' argument of JointVotes.cast must be (T, {len(points)}) rows "
                f"below {self.n_leaves}. Got shape {leaves.shape}, "
                f"largest {leaves.max(initial=-1)}."
            )
        wanted = np.zeros(N_JOINTS, dtype=bool)
        wanted[slice(None) if joints is None else np.asarray(joints, dtype=np.intp)] = True
        if compiled and _ckernels is not None:
            return self._cast_compiled(points, leaves, wanted)
        reached = leaves >= 0
        rows = leaves[reached]
        owner = np.broadcast_to(np.arange(points.shape[0]), leaves.shape)[reached]
        live = self.weight[rows] > 0
        live &= np.append(wanted, False)[self.joint[rows]]  # the last entry: index -1
        slot, k = np.nonzero(live)
        leaf = rows[slot]
        where = points[owner[slot]] + self.offset[leaf, k]
        share = self.weight[leaf, k] / max(len(leaves), 1)
        return where, self.joint[leaf, k].astype(np.int64), share.astype(float)

    def _cast_compiled(self, points, leaves, wanted):
        """:meth:`cast` by the compiled kernel (``_ckernels.c``): the same votes."""
        leaves = np.ascontiguousarray(leaves, dtype=np.int32)
        capacity = leaves.size * self.joint.shape[1]
        where = np.empty((capacity, 3))
        joint = np.empty(capacity, dtype=np.int64)
        share = np.empty(capacity)
        m = _ckernels.cast(
            points, leaves, self.joint, self.offset, self.weight, wanted.view(np.uint8),
            where, joint, share,
        )  # fmt: skip
        return where[:m], joint[:m], share[:m]


def joint_modes(
    where: np.ndarray,
    joint: np.ndarray,
    weight: np.ndarray,
    seeds: np.ndarray,
    *,
    bandwidth: float = 0.05,
    iterations: int = 8,
    min_weight: float = 0.5,
    joints: np.ndarray | None = None,
) -> np.ndarray:
    """Each joint's mode of its votes, climbed from a starting guess (mean shift).

    Parameters
    ----------
    where, joint, weight :
        Votes as :meth:`JointVotes.cast` returns them.
    seeds : (15, 3) float
        Where each joint's climb starts (a NaN row: its votes' weighted mean).
    bandwidth : float
        Gaussian kernel width, metres.
    iterations : int
        Mean-shift steps.
    min_weight : float
        Least total vote weight for a joint to be placed.
    joints : sequence of int, optional
        Only these joints (indices); the others are NaN. Default all.

    Returns
    -------
    (15, 3) float
        NaN for joints with too little weight, or whose climb left every vote behind.

    Examples
    --------
    >>> import numpy as np
    >>> where = np.array([[0.0, 0.0, 2.0], [0.01, 0.0, 2.0], [0.5, 0.0, 2.0]])
    >>> seeds = np.full((15, 3), np.nan); seeds[0] = [0.02, 0.0, 2.0]
    >>> modes = joint_modes(where, np.zeros(3, int), np.ones(3), seeds)
    >>> np.round(modes[0], 3).tolist(), bool(np.isnan(modes[1]).all())
    ([0.005, 0.0, 2.0], True)
    """
    out = np.full((N_JOINTS, 3), np.nan)
    where = np.asarray(where, dtype=float).reshape(-1, 3)
    joint = np.asarray(joint, dtype=np.intp)
    weight = np.asarray(weight, dtype=float)
    if joints is not None:  # drop the other joints' votes: less to climb through
        wanted = np.zeros(N_JOINTS, dtype=bool)
        wanted[np.asarray(joints, dtype=np.intp)] = True
        keep = wanted[joint]
        if not keep.all():  # (votes cast for these joints only need no copies)
            where, joint, weight = where[keep], joint[keep], weight[keep]
    total = np.bincount(joint, weight, minlength=N_JOINTS)
    live = total >= min_weight
    if not live.any():
        return out
    # All joints climb together (skeleton's grouped mean shift); an unseeded joint
    # starts from its votes' weighted mean.
    x = np.array(seeds, dtype=float)
    unseeded = live & ~np.isfinite(x).all(axis=1)
    if unseeded.any():  # (never where every joint is seeded, as the tracker seeds them)
        for c in range(3):
            x[unseeded, c] = (
                np.bincount(joint, weight * where[:, c], minlength=N_JOINTS)[unseeded]
                / total[unseeded]
            )
    _shift_modes(
        where,
        joint,
        weight,
        x,
        live,
        scale=-0.5 / bandwidth**2,
        max_iter=iterations,
        tol=0.0,
        min_mass=1e-9,
        drop_lost=True,  # a climb that left every vote behind places nothing
    )
    out[live] = x[live]
    return out


def fit_joint_votes(
    forest,
    frames: Iterable,
    *,
    n_frames: int,
    radius: float = 0.2,
    per_leaf: int = 4,
    pixels_per_frame: int = 800,
    min_samples: int = 3,
    rng: int | np.random.Generator | None = None,
    on_frame: Callable[[int], None] | None = None,
) -> JointVotes:
    """Learn each leaf's joint offsets from frames with known joints.

    Parameters
    ----------
    forest : BodyPartForest
        Its trees are kept as they are.
    frames : iterable of LabelledFrame
        With ``joints`` (camera frame, metres); at most ``n_frames`` are used.
    n_frames : int
    radius : float
        Pixels farther than this from a joint do not vote for it (metres).
    per_leaf : int
        Votes kept per leaf: the joints most of its pixels were near.
    pixels_per_frame : int
        Foreground pixels drawn per frame, uniformly.
    min_samples : int
        Fewest training pixels behind a kept vote.
    rng : int, Generator or None
        Seeds the pixel draw.
    on_frame : callable, optional
        Called with each frame's index when it is done.

    Returns
    -------
    JointVotes
        For ``forest.with_votes``.

    Raises
    ------
    ValueError
        If a frame has no joints, or no frame has a foreground pixel.
    """
    from posedrift.camera import backproject

    rng = check_rng(rng)
    radius = check_scalar(radius, "radius", low=0.0, caller="fit_joint_votes")
    per_leaf = check_scalar(
        per_leaf,
        "per_leaf",
        low=1,
        high=N_JOINTS,
        include_low=True,
        include_high=True,
        integer=True,
        caller="fit_joint_votes",
    )
    n_leaves = len(forest.leaf_values)
    sums = np.zeros((n_leaves, N_JOINTS, 3))
    near = np.zeros((n_leaves, N_JOINTS))
    seen = np.zeros(n_leaves)
    for i, frame in enumerate(frames):
        if i >= n_frames:
            break
        if frame.joints is None:
            raise ValueError(f"fit_joint_votes needs frames with joints; frame {i} has none.")
        points, pixels = backproject(frame.depth, frame.intrinsics, frame.mask)
        if len(points) > pixels_per_frame:
            keep = rng.choice(len(points), pixels_per_frame, replace=False)
            points, pixels = points[keep], pixels[keep]
        if len(points):
            offset = frame.joints[None, :, :] - points[:, None, :]
            close = np.einsum("njk,njk->nj", offset, offset) < radius**2
            _, leaves = forest.predict_pixels(
                frame.depth, pixels, frame.intrinsics, mask=frame.mask, return_leaves=True
            )
            for rows in leaves:
                np.add.at(seen, rows, 1.0)
                np.add.at(near, rows, close)
                np.add.at(sums, rows, offset * close[..., None])
        if on_frame is not None:
            on_frame(i)
    if not seen.any():
        raise ValueError("fit_joint_votes got no foreground pixel in its frames.")
    share = np.where(near >= min_samples, near / np.maximum(seen, 1.0)[:, None], 0.0)
    top = np.argsort(-share, axis=1, kind="stable")[:, :per_leaf]
    weight = np.take_along_axis(share, top, axis=1)
    count = np.take_along_axis(near, top, axis=1)
    offset = np.take_along_axis(sums, top[..., None], axis=1) / np.maximum(count, 1.0)[..., None]
    joint = np.where(weight > 0, top, -1)
    offset[weight <= 0] = 0.0
    return JointVotes(joint=joint, offset=offset, weight=weight, radius=radius)
