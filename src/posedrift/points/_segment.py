"""Person segmentation in a depth frame: depth gating, background model, floor removal, CC.

Works on synthetic frames (empty background) and real ones (walls, furniture,
floor). Every step is a pure function of arrays; :func:`segment_person` chains them.
"""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_rng, check_scalar
from posedrift.camera import DepthFrame, Intrinsics, backproject


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
        with np.errstate(all="ignore"):
            import warnings

            with warnings.catch_warnings():
                warnings.simplefilter("ignore", RuntimeWarning)
                bg = np.nanquantile(stack, self.quantile, axis=0)
        self.depth_ = np.nan_to_num(bg, nan=0.0).astype(np.float32)
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
    rng : int, Generator or None

    Returns
    -------
    (normal (3,), offset) or None
        The unit normal points along ``up``; ``None`` where no floor is found.
    """
    points = np.asarray(points, dtype=float)
    if len(points) < max(3, min_inliers):
        return None
    gen = check_rng(rng)
    up = np.asarray(up, dtype=float)
    up = up / np.linalg.norm(up)
    cos_tilt = np.cos(np.radians(max_tilt_deg))
    sample = points if len(points) <= 3000 else points[gen.choice(len(points), 3000, replace=False)]
    scale = len(points) / len(sample)
    tri = gen.integers(0, len(sample), size=(iterations, 3))
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
    # A floor lies below (almost) everything else: most points are on its upper side.
    signed = points @ normal - normal @ centre
    if np.mean(signed < -2 * threshold) > 0.05:
        return None
    return normal, float(-normal @ centre)


def _components(mask: np.ndarray, depth: np.ndarray, max_step: float) -> tuple[np.ndarray, int]:
    """Connected components of ``mask`` where 4-neighbours closer than ``max_step`` in depth join."""
    from scipy import ndimage

    # Cut pixels at depth discontinuities, label, then give cut pixels their neighbours' label.
    d = np.where(mask, depth, 0.0)
    jump = np.zeros(mask.shape, dtype=bool)
    dv = np.abs(np.diff(d, axis=0)) > max_step
    dh = np.abs(np.diff(d, axis=1)) > max_step
    # The farther pixel of a jump is the one that is cut.
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
    rng: int | np.random.Generator | None = 0,
) -> np.ndarray:
    """The person's pixels in a depth frame.

    Steps: depth gating to ``[min_depth, max_depth]``; the background model's
    foreground (static cameras); removal of a floor plane found by RANSAC; the
    largest connected component (joined across depth steps below
    ``max_depth_step``) that is tall enough to be a person.

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
    rng : int, Generator or None
        Seeds the floor RANSAC.

    Returns
    -------
    mask : (H, W) bool
        All False where no person is found.

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
        depth = frame.depth
        intrinsics = frame.intrinsics
    else:
        depth = np.asarray(frame, dtype=np.float32)
        if depth.ndim != 2:
            raise ValueError(
                f"The 'frame' argument of segment_person must be a DepthFrame or a 2-D depth "
                f"image. Got shape {depth.shape}."
            )
    depth = np.where(np.isfinite(depth), depth, 0.0).astype(np.float32, copy=False)
    mask = (depth >= min_depth) & (depth <= max_depth)
    if background is not None:
        mask &= background.foreground(depth)
    if not mask.any():
        return mask
    if remove_floor and intrinsics is not None and mask.sum() >= min_pixels:
        points, pixels = backproject(depth, intrinsics, mask)
        plane = fit_floor_plane(points, threshold=floor_threshold, rng=rng)
        if plane is not None:
            normal, offset = plane
            height = points @ normal + offset
            on_floor = height < floor_threshold
            mask[pixels[on_floor, 0], pixels[on_floor, 1]] = False
    labels, n = _components(mask, depth, max_depth_step)
    if n == 0:
        return np.zeros_like(mask)
    counts = np.bincount(labels.ravel(), minlength=n + 1)
    counts[0] = 0
    order = np.argsort(counts)[::-1]
    chosen = 0
    for lab in order[: min(n, 5)]:
        if counts[lab] < min_pixels:
            break
        rows = np.nonzero((labels == lab).any(axis=1))[0]
        if intrinsics is not None:
            z = float(np.median(depth[labels == lab]))
            extent = (rows[-1] - rows[0] + 1) * z / intrinsics.fy
            if extent < min_height:
                continue
        chosen = lab
        break
    if chosen == 0:
        return np.zeros_like(mask)
    person = labels == chosen
    # Give back the pixels cut at depth steps that touch the person and match its depth.
    from scipy import ndimage

    ring = ndimage.binary_dilation(person) & mask & (labels == 0)
    if ring.any():
        near = ndimage.grey_dilation(np.where(person, depth, 0.0), size=3)
        person |= ring & (np.abs(depth - near) < max_depth_step)
    return person
