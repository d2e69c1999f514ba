"""Person segmentation in a depth frame: depth gating, background model, floor removal, CC.

Works on synthetic frames (empty background) and real ones (walls, furniture,
floor). Every step is a pure function of arrays; :func:`segment_person` chains them.
"""

from __future__ import annotations

import numpy as np

from posedrift._stats import median
from posedrift._validation import check_rng, check_scalar
from posedrift.camera import DepthFrame, Intrinsics

try:  # the compiled kernel is optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.points import _cpoints  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _cpoints = None


class BackgroundModel:
    """A per-pixel background depth for a static camera.

    The background depth of a pixel is a high quantile of the depths seen there
    (a person moves, the wall does not); a pixel is foreground where it is nearer
    than its background by more than ``margin``, or where no background is known.

    Parameters
    ----------
    margin : float
        Metres a pixel must be in front of the background to count as foreground.
    quantile : float
        Quantile of the observed depths taken as the background, in (0, 1].

    Examples
    --------
    >>> import numpy as np
    >>> wall = np.full((4, 5), 3.0, dtype=np.float32)
    >>> model = BackgroundModel().fit([wall, wall])
    >>> frame = wall.copy(); frame[1, 2] = 2.0
    >>> model.foreground(frame).sum()
    np.int64(1)
    """

    def __init__(self, *, margin: float = 0.1, quantile: float = 0.9) -> None:
        self.margin = check_scalar(margin, "margin", low=0.0, caller="BackgroundModel")
        self.quantile = check_scalar(
            quantile, "quantile", low=0.0, high=1.0, include_high=True, caller="BackgroundModel"
        )
        self.depth_: np.ndarray | None = None

    def fit(self, depths) -> BackgroundModel:
        """Learn the background from a stack of depth images ``(T, H, W)`` in metres."""
        stack = np.asarray([np.asarray(d, dtype=np.float32) for d in depths], dtype=np.float32)
        if stack.ndim != 3 or len(stack) == 0:
            raise ValueError(
                "The 'depths' argument of BackgroundModel.fit must be a non-empty stack of "
                f"2-D depth images. Got shape {stack.shape}."
            )
        stack = np.where(np.isfinite(stack) & (stack > 0), stack, np.nan)
        count = np.sum(~np.isnan(stack), axis=0)
        ordered = np.sort(stack, axis=0)  # NaN (no measurement) sorts last
        index = np.floor(self.quantile * np.maximum(count - 1, 0)).astype(np.intp)
        bg = np.take_along_axis(ordered, index[None], axis=0)[0]
        self.depth_ = np.where(count > 0, bg, 0.0).astype(np.float32)
        return self

    def foreground(self, depth: np.ndarray) -> np.ndarray:
        """Foreground mask ``(H, W)`` bool of a depth image (metres)."""
        if self.depth_ is None:
            raise ValueError("This BackgroundModel is not fitted yet: call fit(depths) first.")
        depth = np.asarray(depth, dtype=np.float32)
        if depth.shape != self.depth_.shape:
            raise ValueError(
                f"The 'depth' image must have the background's shape {self.depth_.shape}. "
                f"Got {depth.shape} instead."
            )
        bg = self.depth_
        return (depth > 0) & ((bg <= 0) | (depth < bg - self.margin))


def fit_floor_plane(
    points: np.ndarray,
    *,
    up: np.ndarray = (0.0, -1.0, 0.0),
    max_tilt_deg: float = 35.0,
    threshold: float = 0.03,
    iterations: int = 60,
    min_inliers: int = 200,
    min_extent: float = 1.0,
    rng: int | np.random.Generator | None = 0,
) -> tuple[np.ndarray, float] | None:
    """RANSAC for a floor plane ``n . x + d = 0`` roughly perpendicular to ``up``.

    Parameters
    ----------
    points : (N, 3) float
        Camera-frame points in metres.
    up : (3,) float
        The expected upward direction in the camera frame (``-Y`` for a level camera).
    max_tilt_deg : float
        Largest accepted angle between the plane's normal and ``up``.
    threshold : float
        Inlier distance in metres.
    iterations : int
    min_inliers : int
        Fewest inliers for a plane to count as the floor.
    min_extent : float
        Smallest extent (metres) of the inliers along the plane.
    rng : int, Generator or None

    Returns
    -------
    (normal (3,), offset) or None
        The unit normal points along ``up``; ``None`` where no floor is found.
    """
    points = np.asarray(points, dtype=float)
    return _floor_plane(
        len(points),
        lambda index: points if index is None else points[index],
        up=up,
        max_tilt_deg=max_tilt_deg,
        threshold=threshold,
        iterations=iterations,
        min_inliers=min_inliers,
        min_extent=min_extent,
        rng=rng,
    )


def _floor_plane(
    count: int,
    take,
    *,
    up,
    max_tilt_deg: float,
    threshold: float,
    iterations: int,
    min_inliers: int,
    min_extent: float,
    rng,
    known: tuple[np.ndarray, float] | None = None,
) -> tuple[np.ndarray, float] | None:
    """:func:`fit_floor_plane` on ``count`` points read through ``take``.

    ``take(index)`` returns the points at ``index`` (all of them for ``None``), so a
    caller can compute only the RANSAC sample and, where a plane is found, the rest.
    A ``known`` plane (the last frame's) is returned as it is where it still holds
    ``min_inliers`` points and lies below the others; else RANSAC runs.
    """
    if count < max(3, min_inliers):
        return None
    gen = check_rng(rng)
    up = np.asarray(up, dtype=float)
    up = up / np.linalg.norm(up)
    cos_tilt = np.cos(np.radians(max_tilt_deg))
    sample = take(None) if count <= 3000 else take(gen.choice(count, 3000, replace=False))
    scale = count / len(sample)
    if known is not None:
        normal, offset = known
        on_plane = np.count_nonzero(np.abs(sample @ normal + offset) < threshold)
        if on_plane * scale >= min_inliers and _below_the_rest(take, normal, offset, threshold):
            return known
    # Hypotheses from the lowest quarter of the points (where a floor must be).
    low = np.argpartition(sample @ up, max(3, len(sample) // 4) - 1)[: max(3, len(sample) // 4)]
    lowest = sample[low]
    # Per-column extents (much faster than an axis-0 reduction of an (N, 3) array).
    if max(float(np.ptp(lowest[:, d])) for d in range(3)) < min_extent:
        return None  # the lowest points are too compact to be a floor (feet)
    tri = low[gen.integers(0, len(low), size=(iterations, 3))]
    a, b, c = sample[tri[:, 0]], sample[tri[:, 1]], sample[tri[:, 2]]
    normals = np.cross(b - a, c - a)
    norms = np.linalg.norm(normals, axis=1)
    ok = norms > 1e-9
    normals[ok] /= norms[ok, None]
    flip = normals @ up < 0
    normals[flip] *= -1
    ok &= normals @ up > cos_tilt
    if not ok.any():
        return None
    normals, a = normals[ok], a[ok]
    offsets = -np.einsum("ij,ij->i", normals, a)
    dist = np.abs(sample @ normals.T + offsets)  # (S, K)
    counts = (dist < threshold).sum(axis=0)
    best = int(np.argmax(counts))
    if counts[best] * scale < min_inliers:
        return None
    inl = sample[dist[:, best] < threshold]
    # Refine by least squares on the inliers.
    centre = inl.mean(axis=0)
    _, _, vt = np.linalg.svd(inl - centre, full_matrices=False)
    normal = vt[-1]
    if normal @ up < 0:
        normal = -normal
    if normal @ up < cos_tilt:
        normal = normals[best]
        centre = a[best]
    # A floor is wide (not the top of a foot) ...
    if np.ptp(inl - (inl @ normal)[:, None] * normal, axis=0).max() < min_extent:
        return None
    # ... and lies below (almost) everything else: most points are on its upper side.
    offset = float(-normal @ centre)
    if not _below_the_rest(take, normal, offset, threshold):
        return None
    return normal, offset


def _below_the_rest(take, normal: np.ndarray, offset: float, threshold: float) -> bool:
    """Whether at most 5% of the points lie more than ``2 threshold`` under a plane."""
    return bool(np.mean(take(None) @ normal + offset < -2 * threshold) <= 0.05)


def _backproject_pixels(depth: np.ndarray, intrinsics: Intrinsics, rows, cols) -> np.ndarray:
    """Eq. 1 at the given pixels: ``(N, 3)`` points, as :func:`posedrift.camera.backproject`."""
    z = depth[rows, cols].astype(float)
    x = (cols - intrinsics.cx) * z / intrinsics.fx
    y = (rows - intrinsics.cy) * z / intrinsics.fy
    return np.column_stack([x, y, z])


def _nonzero(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``np.nonzero(mask)`` of a 2-D mask (row-major order), several times faster."""
    rows, cols = np.divmod(np.flatnonzero(mask), mask.shape[1])
    return rows, cols


def _max3x3(image: np.ndarray) -> np.ndarray:
    """Maximum over each pixel's 3 x 3 neighbourhood (within the image).

    The same as ``scipy.ndimage.grey_dilation(image, size=3)`` (whose reflected border
    only repeats pixels already in the window), by two separable passes.
    """
    cols = image.copy()
    np.maximum(cols[1:], image[:-1], out=cols[1:])
    np.maximum(cols[:-1], image[1:], out=cols[:-1])
    out = cols.copy()
    np.maximum(out[:, 1:], cols[:, :-1], out=out[:, 1:])
    np.maximum(out[:, :-1], cols[:, 1:], out=out[:, :-1])
    return out


def _dilate(mask: np.ndarray, iterations: int = 1) -> np.ndarray:
    """Binary dilation by the 4-neighbour cross, zero outside the image.

    The same as ``scipy.ndimage.binary_dilation(mask, iterations=iterations)``. Worked
    on the flattened image with a False column appended to each row, so that every
    shift is one contiguous operation (a row's neighbours across the wrap are that
    column, cleared again after each step): a third faster than row-wise 2-D shifts.
    """
    height, width = mask.shape
    padded = np.zeros((height, width + 1), dtype=bool)
    padded[:, :width] = mask
    out = padded.reshape(-1)
    row = width + 1
    for _ in range(iterations):
        prev = out.copy()
        out[row:] |= prev[:-row]
        out[:-row] |= prev[row:]
        out[1:] |= prev[:-1]
        out[:-1] |= prev[1:]
        padded[:, width] = False
    return padded[:, :width]


def _components(
    mask: np.ndarray, depth: np.ndarray, max_step: float, compiled: bool = True
) -> tuple[np.ndarray, int]:
    """Components of ``mask``; 4-neighbours join where their depths differ by < ``max_step``.

    ``depth`` is float32 (as :func:`segment_person` makes it). The compiled kernel, where
    built, gives the same labels as the NumPy and SciPy code below.
    """
    if compiled and _cpoints is not None and depth.dtype == np.float32:
        labels = np.empty(mask.shape, dtype=np.int32)
        count = _cpoints.components(
            np.ascontiguousarray(mask, dtype=np.uint8),
            np.ascontiguousarray(depth),
            mask.shape[0],
            mask.shape[1],
            float(max_step),
            labels,
        )
        return labels, count
    from scipy import ndimage

    # Cut pixels at depth discontinuities, label, then give cut pixels their neighbours' label.
    d = np.zeros(depth.shape, dtype=np.result_type(depth, 0.0))
    np.copyto(d, depth, where=mask)  # np.where(mask, depth, 0.0), faster
    jump = np.zeros(mask.shape, dtype=bool)
    # Only steps between two kept pixels count (the silhouette's own edge is no step).
    dv = (np.abs(np.diff(d, axis=0)) > max_step) & mask[1:] & mask[:-1]
    dh = (np.abs(np.diff(d, axis=1)) > max_step) & mask[:, 1:] & mask[:, :-1]
    # The farther pixel of a step is the one that is cut.
    far_v = d[1:] > d[:-1]
    jump[1:] |= dv & far_v
    jump[:-1] |= dv & ~far_v
    far_h = d[:, 1:] > d[:, :-1]
    jump[:, 1:] |= dh & far_h
    jump[:, :-1] |= dh & ~far_h
    core = mask & ~jump
    labels, n = ndimage.label(core)
    return labels, n


def segment_person(
    frame: DepthFrame | np.ndarray,
    intrinsics: Intrinsics | None = None,
    *,
    background: BackgroundModel | None = None,
    min_depth: float = 0.4,
    max_depth: float = 6.0,
    remove_floor: bool = True,
    floor_threshold: float = 0.03,
    max_depth_step: float = 0.15,
    min_pixels: int = 150,
    min_height: float = 0.4,
    max_join_depth: float = 0.6,
    max_extent: float = 2.6,
    rng: int | np.random.Generator | None = 0,
    floor: tuple[np.ndarray, float] | None = None,
    return_floor: bool = False,
) -> np.ndarray | tuple[np.ndarray, tuple[np.ndarray, float] | None]:
    """The person's pixels in a depth frame.

    Steps: depth gating to ``[min_depth, max_depth]``; the background model's
    foreground (static cameras); removal of a floor plane found by RANSAC; the
    largest connected component (joined across depth steps below
    ``max_depth_step``) whose size fits a person, with the touching
    components at a similar depth (a limb in front of the body).

    Parameters
    ----------
    frame : DepthFrame or (H, W) float
        Depth in metres (0 where unknown).
    intrinsics : Intrinsics, optional
        Needed when ``frame`` is a bare array and ``remove_floor`` is set.
    background : BackgroundModel, optional
    min_depth, max_depth : float
        Depth gate in metres.
    remove_floor : bool
    floor_threshold : float
        Points within this many metres of the floor plane are dropped.
    max_depth_step : float
        Neighbouring pixels further apart in depth than this (metres) are not joined.
    min_pixels : int
        Fewest pixels of a person; smaller components are ignored.
    min_height : float
        Smallest physical extent (metres, image vertical) of a person.
    max_extent : float
        Largest height or width (metres) of a person; larger components are
        background (walls, floor).
    max_join_depth : float
        Components touching the person in the image whose median depth is within
        this many metres of the person's are joined to it (limbs in front of the body).
    rng : int, Generator or None
        Seeds the floor RANSAC.
    floor : (normal (3,), offset), optional
        A floor plane to try first, such as the last frame's from a static camera:
        kept where it still holds enough of this frame's points and lies below the
        rest, else RANSAC looks for the floor afresh.
    return_floor : bool
        Also return the floor plane used (``None`` where none was found).

    Returns
    -------
    mask : (H, W) bool
        All False where no person is found.
    floor : (normal (3,), offset) or None
        Only with ``return_floor``.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import camera_preset
    >>> k = camera_preset("kinect1-qvga")
    >>> depth = np.zeros(k.shape, np.float32); depth[40:200, 140:180] = 2.8
    >>> int(segment_person(depth, k).sum())
    6400
    """
    if isinstance(frame, DepthFrame):
        depth = frame.depth  # float32 and finite already (DepthFrame sees to it)
        intrinsics = frame.intrinsics
    else:
        depth = np.asarray(frame, dtype=np.float32)
        if depth.ndim != 2:
            raise ValueError(
                f"The 'frame' argument of segment_person must be a DepthFrame or a 2-D depth "
                f"image. Got shape {depth.shape}."
            )
        finite = np.isfinite(depth)
        if not finite.all():
            depth = np.where(finite, depth, 0.0).astype(np.float32, copy=False)
    mask = (depth >= min_depth) & (depth <= max_depth)
    if background is not None:
        mask &= background.foreground(depth)
    plane = None

    def done(person: np.ndarray):
        return (person, plane) if return_floor else person

    if not mask.any():
        return done(mask)
    if remove_floor and intrinsics is not None and np.count_nonzero(mask) >= min_pixels:
        # The floor's RANSAC sample is back-projected alone; every pixel only where a
        # plane is found (Eq. 1 per pixel: the same points as backproject(depth, mask)).
        rows, cols = _nonzero(mask if min_depth > 0 else mask & (depth > 0))
        every: list[np.ndarray] = []

        def take(index):
            if index is not None:
                return _backproject_pixels(depth, intrinsics, rows[index], cols[index])
            if not every:
                every.append(_backproject_pixels(depth, intrinsics, rows, cols))
            return every[0]

        options = dict(fit_floor_plane.__kwdefaults__, threshold=floor_threshold, rng=rng)
        plane = _floor_plane(len(rows), take, known=floor, **options)
        if plane is not None:
            normal, offset = plane
            height = take(None) @ normal + offset
            on_floor = height < floor_threshold
            mask[rows[on_floor], cols[on_floor]] = False
            if not mask.any():
                return done(mask)
    # Work on the bounding box of the gated pixels (the person is a small part of a frame).
    rows = np.nonzero(mask.any(axis=1))[0]
    cols = np.nonzero(mask.any(axis=0))[0]
    r0, r1 = max(rows[0] - 3, 0), min(rows[-1] + 4, mask.shape[0])
    c0, c1 = max(cols[0] - 3, 0), min(cols[-1] + 4, mask.shape[1])
    out = np.zeros_like(mask)
    out[r0:r1, c0:c1] = _largest_person(
        mask[r0:r1, c0:c1],
        depth[r0:r1, c0:c1],
        intrinsics,
        max_depth_step=max_depth_step,
        min_pixels=min_pixels,
        min_height=min_height,
        max_extent=max_extent,
        max_join_depth=max_join_depth,
    )
    return done(out)


_FEW_COMPONENTS = 4  # components counted one by one (_largest_person)


def _largest_person(
    mask,
    depth,
    intrinsics,
    *,
    max_depth_step,
    min_pixels,
    min_height,
    max_extent,
    max_join_depth,
) -> np.ndarray:
    """The person-sized largest component of ``mask``, with limbs split off by depth steps."""
    labels, n = _components(mask, depth, max_depth_step)
    if n == 0:
        return np.zeros_like(mask)
    if n <= _FEW_COMPONENTS:  # a pass per component beats bincount's passes over every pixel
        counts = np.array([0] + [np.count_nonzero(labels == lab) for lab in range(1, n + 1)])
    else:
        counts = np.bincount(labels.ravel(), minlength=n + 1)
        counts[0] = 0
    order = np.argsort(counts)[::-1]
    chosen = 0
    z_person = person = None
    for lab in order[: min(n, 8)]:
        if counts[lab] < min_pixels:
            break
        if intrinsics is not None:
            person = labels == lab  # kept with its median depth if it is chosen
            rows = np.nonzero(person.any(axis=1))[0]
            cols = np.nonzero(person.any(axis=0))[0]
            z = z_person = median(depth[person])
            tall = (rows[-1] - rows[0] + 1) * z / intrinsics.fy
            wide = (cols[-1] - cols[0] + 1) * z / intrinsics.fx
            if tall < min_height or tall > max_extent or wide > max_extent:
                continue  # too small, or a wall / the floor
        chosen = lab
        break
    if chosen == 0:
        return np.zeros_like(mask)
    if person is None:
        person = labels == chosen
    # Parts split off by depth steps (an arm in front of the chest) rejoin the person
    # when they touch it in the image and lie at a similar depth.
    if z_person is None:
        z_person = median(depth[person])
    near = _dilate(person, iterations=2)
    touching = np.unique(labels[near & (labels > 0) & ~person])
    for lab in touching:
        part = labels == lab
        if abs(median(depth[part]) - z_person) < max_join_depth:
            person |= part
    # Give back the pixels cut at depth steps that touch the person and match its depth.
    ring = _dilate(person) & mask & (labels == 0)
    if ring.any():
        near_depth = _max3x3(np.where(person, depth, 0.0))
        person |= ring & (np.abs(depth - near_depth) < max_depth_step)
    return person
