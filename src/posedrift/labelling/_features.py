"""Depth-comparison features (Shotton et al. 2011): pure array kernels.

``f(I, x) = d(x + u / d(x)) - d(x + v / d(x))``. The offsets ``u`` and ``v`` are
stored in pixel x metres at a reference focal length (:data:`REFERENCE_FOCAL`, the
Kinect v1 QVGA camera); at another camera they are scaled by ``f / f_ref`` so the
same model serves any resolution. A probe that lands off the image or on a pixel
outside the foreground mask reads the large constant depth ``background``.

Training (the outer product of pixels and offset pairs) and inference (one offset
pair per pixel, chosen by the tree) share the same elementwise float32 operations
in the same order, so a threshold learnt on training features routes an inference
pixel exactly as it would have routed the same feature at training time.

References
----------
J. Shotton et al., "Real-time human pose recognition in parts from single depth
images", CVPR 2011. doi:10.1109/CVPR.2011.5995316
"""

from __future__ import annotations

import numpy as np

from posedrift.camera import Intrinsics

try:  # the compiled kernels are optional: built by ``pip install -e .`` when a compiler exists
    from posedrift.labelling import _ckernels  # type: ignore[attr-defined]
except ImportError:  # pragma: no cover - depends on the build
    _ckernels = None

REFERENCE_FOCAL = 285.63
"""Focal length (pixels) at which offsets are expressed: Kinect v1 depth at 320 x 240."""

BACKGROUND_DEPTH = 10.0
"""Depth (metres) read by probes that land off the image or on background."""


def probe_image(depth: np.ndarray, mask: np.ndarray, background: float) -> np.ndarray:
    """The image that probes read, with a one-pixel background border, flattened.

    Parameters
    ----------
    depth : (H, W) float
        Depth in metres.
    mask : (H, W) bool
        Foreground pixels; every other pixel reads ``background``.
    background : float
        Depth in metres of background and off-image probes.

    Returns
    -------
    image : ((H + 2) * (W + 2),) float32
        Row-major; pixel ``(r, c)`` sits at ``(r + 1) * (W + 2) + c + 1``.
    """
    height, width = depth.shape
    padded = np.full((height + 2, width + 2), background, dtype=np.float32)
    inner = padded[1:-1, 1:-1]
    np.copyto(inner, depth, where=mask, casting="unsafe")
    return padded.ravel()


def checked_frame(
    depth: np.ndarray, mask: np.ndarray | None, intrinsics: Intrinsics, caller: str
) -> tuple[np.ndarray, np.ndarray]:
    """A labeller's frame checked once: ``(depth as float32, foreground)``.

    The foreground is the pixels with finite, positive depth, within ``mask`` where
    one is given. Messages name ``caller`` (``"BodyPartForest.predict"``).

    Raises
    ------
    ValueError
        If ``intrinsics`` is not an :class:`Intrinsics`, ``depth`` is not a numeric
        image of its shape, or ``mask`` has another shape.
    """
    depth = np.asarray(depth)
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(
            f"The 'intrinsics' argument of {caller} must be an Intrinsics. "
            f"Got {type(intrinsics).__name__} instead."
        )
    if depth.ndim != 2 or depth.shape != intrinsics.shape:
        raise ValueError(
            f"The 'depth' argument of {caller} must be an image of shape "
            f"{intrinsics.shape} (the intrinsics'). Got shape {depth.shape} instead."
        )
    if not np.issubdtype(depth.dtype, np.number):
        raise ValueError(
            f"The 'depth' argument of {caller} must hold numbers. Got dtype {depth.dtype} instead."
        )
    depth = depth.astype(np.float32, copy=False)
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        mask = np.asarray(mask)
        if mask.shape != depth.shape:
            raise ValueError(
                f"The 'mask' argument of {caller} must have the depth's shape "
                f"{depth.shape}. Got shape {mask.shape} instead."
            )
        valid &= mask.astype(bool, copy=False)
    return depth, valid


class CheckedPixels:
    """A labeller's frame and pixels checked once, with what their probes read.

    The tracker asks the forest and the part net about the same pixels of the same
    frame: one of these serves both, so the checks, the probe image (one per
    background depth) and the pixel terms (one per reference focal length) are made
    once a frame. ``inside`` marks the pixels in the foreground; the terms are theirs.
    """

    def __init__(
        self,
        depth: np.ndarray,
        mask: np.ndarray | None,
        pixels: np.ndarray,
        intrinsics: Intrinsics,
        caller: str,
    ) -> None:
        self.depth, self.valid = checked_frame(depth, mask, intrinsics, caller)
        self.pixels = checked_pixels(pixels, self.depth.shape, caller)
        self.intrinsics = intrinsics
        at = self.pixels
        self.inside = self.valid[at[:, 0], at[:, 1]] if len(at) else np.zeros(0, bool)
        self._images: dict[float, np.ndarray] = {}
        self._terms: dict[float, tuple[np.ndarray, ...]] = {}

    def image(self, background: float) -> np.ndarray:
        """:func:`probe_image` of the frame."""
        if background not in self._images:
            self._images[background] = probe_image(self.depth, self.valid, background)
        return self._images[background]

    def terms(self, reference_focal: float) -> tuple[np.ndarray, ...]:
        """:func:`pixel_terms` of the pixels ``inside`` the foreground."""
        if reference_focal not in self._terms:
            self._terms[reference_focal] = pixel_terms(
                self.depth, self.pixels[self.inside], self.intrinsics, reference_focal
            )
        return self._terms[reference_focal]


def foreground_pixels(valid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The foreground of a labeller's frame, row-major: ``(flat indices, (N, 2) pixels)``."""
    flat = np.flatnonzero(valid)
    rows, cols = np.divmod(flat, valid.shape[1])
    return flat, np.column_stack([rows, cols]).astype(np.intp)


def checked_pixels(pixels: np.ndarray, shape: tuple[int, int], caller: str) -> np.ndarray:
    """``(N, 2)`` integer ``(row, column)`` pixels inside an image of ``shape``, as intp.

    Raises
    ------
    ValueError
        If ``pixels`` is not an (N, 2) integer array or a pixel lies outside the image.
    """
    pixels = np.asarray(pixels)
    if pixels.ndim != 2 or pixels.shape[1] != 2 or not np.issubdtype(pixels.dtype, np.integer):
        raise ValueError(
            f"The 'pixels' argument of {caller} must be an (N, 2) integer array of "
            f"(row, column). Got dtype {pixels.dtype}, shape {pixels.shape} instead."
        )
    height, width = shape
    if len(pixels) and (
        pixels.min() < 0 or pixels[:, 0].max() >= height or pixels[:, 1].max() >= width
    ):
        raise ValueError(
            f"The 'pixels' argument of {caller} must lie inside the {height} x {width} "
            f"image. Got rows {pixels[:, 0].min()}..{pixels[:, 0].max()}, columns "
            f"{pixels[:, 1].min()}..{pixels[:, 1].max()}."
        )
    return pixels.astype(np.intp, copy=False)


def pixel_terms(
    depth: np.ndarray,
    pixels: np.ndarray,
    intrinsics: Intrinsics,
    reference_focal: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Per-pixel terms of the feature: shifted row and column, and the offset scales.

    Parameters
    ----------
    depth : (H, W) float
        Depth in metres; every listed pixel must have a positive depth.
    pixels : (N, 2) int
        ``(row, column)`` of each pixel.
    intrinsics : Intrinsics
        The camera (its focal lengths scale the offsets).
    reference_focal : float
        Focal length (pixels) at which offsets are expressed.

    Returns
    -------
    rows, cols : (N,) float32
        ``row + 1.5`` and ``column + 1.5`` (border shift and rounding half-up folded in).
    row_scale, col_scale : (N,) float32
        ``(fy / f_ref) / d(x)`` and ``(fx / f_ref) / d(x)``: pixels per (pixel x metre)
        of offset, in 1/metres.
    """
    rows = pixels[:, 0].astype(np.float32) + np.float32(1.5)
    cols = pixels[:, 1].astype(np.float32) + np.float32(1.5)
    flat = pixels[:, 0] * depth.shape[1] + pixels[:, 1]
    d = np.take(depth.reshape(-1), flat).astype(np.float32)
    row_scale = np.float32(intrinsics.fy / reference_focal) / d
    col_scale = np.float32(intrinsics.fx / reference_focal) / d
    return rows, cols, row_scale, col_scale


def probe(
    image: np.ndarray,
    shape: tuple[int, int],
    rows: np.ndarray,
    cols: np.ndarray,
    row_scale: np.ndarray,
    col_scale: np.ndarray,
    offset_rows: np.ndarray,
    offset_cols: np.ndarray,
) -> np.ndarray:
    """Depth read at ``x + offset f / (f_ref d(x))`` (rounded half up), broadcasting.

    Parameters
    ----------
    image : ((H + 2) * (W + 2),) float32
        From :func:`probe_image`.
    shape : (int, int)
        ``(H, W)`` of the unpadded image.
    rows, cols, row_scale, col_scale : float32 arrays
        From :func:`pixel_terms` (broadcast against the offsets).
    offset_rows, offset_cols : float32 arrays
        Offsets in pixel x metres at the reference focal length.

    Returns
    -------
    values : float32 array
        The probed depths, in metres.
    """
    height, width = shape
    # rows already hold r + 1.5: after clipping to the border (0 or H + 1) truncation is the
    # floor, so any probe off the image lands on the background border.
    r = offset_rows * row_scale
    r += rows
    np.clip(r, 0, height + 1, out=r)
    c = offset_cols * col_scale
    c += cols
    np.clip(c, 0, width + 1, out=c)
    index = r.astype(np.int32)
    index *= np.int32(width + 2)
    index += c.astype(np.int32)
    return np.take(image, index)  # much faster than image[index] for 1-D gathers


def pair_features(
    image: np.ndarray,
    shape: tuple[int, int],
    rows: np.ndarray,
    cols: np.ndarray,
    row_scale: np.ndarray,
    col_scale: np.ndarray,
    offsets: np.ndarray,
) -> np.ndarray:
    """``d(x + u / d(x)) - d(x + v / d(x))`` broadcasting pixels against ``offsets[..., 4]``."""
    terms = (image, shape, rows, cols, row_scale, col_scale)
    first = probe(*terms, offsets[..., 0], offsets[..., 1])
    first -= probe(*terms, offsets[..., 2], offsets[..., 3])
    return first


def feature_matrix(
    depth: np.ndarray,
    mask: np.ndarray,
    pixels: np.ndarray,
    offsets: np.ndarray,
    intrinsics: Intrinsics,
    *,
    reference_focal: float,
    background: float,
    out: np.ndarray | None = None,
    chunk: int = 256,
    compiled: bool = True,
) -> np.ndarray:
    """Every offset pair at every listed pixel: the ``(N, K)`` float32 training matrix.

    Inputs are assumed valid (see :func:`depth_features` for the checked entry point).
    With ``compiled`` (and the kernels built) one compiled loop computes it, about ten
    times faster at a few hundred pixels, with the same float32 operations: the same
    values as the NumPy loop (``compiled=False``), which reads ``chunk`` offsets at a time.
    """
    image = probe_image(depth, mask, background)
    terms = pixel_terms(depth, pixels, intrinsics, reference_focal)
    return probed_features(
        image, depth.shape, terms, offsets, out=out, chunk=chunk, compiled=compiled
    )


def probed_features(
    image: np.ndarray,
    shape: tuple[int, int],
    terms: tuple[np.ndarray, ...],
    offsets: np.ndarray,
    *,
    out: np.ndarray | None = None,
    chunk: int = 256,
    compiled: bool = True,
) -> np.ndarray:
    """:func:`feature_matrix` from its :func:`probe_image` and :func:`pixel_terms`."""
    offsets = np.ascontiguousarray(offsets, dtype=np.float32)
    n, k = len(terms[0]), len(offsets)
    if out is None:
        out = np.empty((n, k), dtype=np.float32)
    if compiled and _ckernels is not None and out.flags.c_contiguous and out.dtype == np.float32:
        _ckernels.features(offsets, image, *terms, shape[0], shape[1], out)
        return out
    rows, cols, row_scale, col_scale = terms
    for start in range(0, k, chunk):
        block = offsets[start : start + chunk]
        out[:, start : start + len(block)] = pair_features(
            image,
            shape,
            rows[:, None],
            cols[:, None],
            row_scale[:, None],
            col_scale[:, None],
            block[None, :, :],
        )
    return out


def depth_features(
    depth: np.ndarray,
    pixels: np.ndarray,
    offsets: np.ndarray,
    *,
    intrinsics: Intrinsics,
    mask: np.ndarray | None = None,
    reference_focal: float = REFERENCE_FOCAL,
    background: float = BACKGROUND_DEPTH,
) -> np.ndarray:
    """Depth-comparison features of Shotton et al. at many pixels and offset pairs at once.

    ``f(I, x) = d(x + u / d(x)) - d(x + v / d(x))``, with ``u`` and ``v`` scaled by
    the camera's focal length over ``reference_focal``; a probe off the image or
    outside ``mask`` reads ``background``. Probes round half up to the nearest pixel.

    Parameters
    ----------
    depth : (H, W) float
        Depth in metres.
    pixels : (N, 2) int
        ``(row, column)`` of the pixels; each must be foreground with positive depth.
    offsets : (K, 4) float
        ``(u_row, u_col, v_row, v_col)`` in pixel x metres at ``reference_focal``.
    intrinsics : Intrinsics
        The camera; its shape must match ``depth``.
    mask : (H, W) bool, optional
        Foreground. Defaults to the pixels with positive, finite depth.
    reference_focal : float
        Focal length in pixels at which ``offsets`` are expressed.
    background : float
        Depth in metres read by background and off-image probes.

    Returns
    -------
    features : (N, K) float32
        Depth differences in metres.

    Raises
    ------
    ValueError
        If a shape does not match or a pixel is off the image, background, or has no depth.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import Intrinsics
    >>> cam = Intrinsics(fx=10.0, fy=10.0, cx=2.0, cy=2.0, width=4, height=4)
    >>> depth = np.full((4, 4), 2.0)
    >>> depth[:, 2:] = 3.0
    >>> offsets = np.array([[0.0, 2.0, 0.0, 0.0], [0.0, -20.0, 0.0, 0.0]])
    >>> depth_features(depth, [[1, 1]], offsets, intrinsics=cam, reference_focal=10.0)
    array([[1., 8.]], dtype=float32)
    """
    depth = np.asarray(depth, dtype=np.float32)
    if depth.ndim != 2 or depth.shape != intrinsics.shape:
        raise ValueError(
            f"The 'depth' argument of depth_features must be an image of shape "
            f"{intrinsics.shape} (the intrinsics'). Got shape {depth.shape} instead."
        )
    valid = np.isfinite(depth) & (depth > 0)
    if mask is None:
        mask = valid
    else:
        mask = np.asarray(mask, dtype=bool)
        if mask.shape != depth.shape:
            raise ValueError(
                f"The 'mask' argument of depth_features must have the depth's shape "
                f"{depth.shape}. Got shape {mask.shape} instead."
            )
        mask = mask & valid
    pixels = np.asarray(pixels)
    if pixels.ndim != 2 or pixels.shape[1] != 2 or not np.issubdtype(pixels.dtype, np.integer):
        raise ValueError(
            f"The 'pixels' argument of depth_features must be an (N, 2) integer array of "
            f"(row, column). Got shape {pixels.shape}, dtype {pixels.dtype} instead."
        )
    inside = (
        (pixels[:, 0] >= 0)
        & (pixels[:, 0] < depth.shape[0])
        & (pixels[:, 1] >= 0)
        & (pixels[:, 1] < depth.shape[1])
    )
    ok = inside.copy()
    ok[inside] = mask[pixels[inside, 0], pixels[inside, 1]]
    if not ok.all():
        raise ValueError(
            f"The 'pixels' of depth_features must be foreground pixels with positive depth "
            f"inside the image. Got {int(np.count_nonzero(~ok))} that are not, "
            f"the first at {tuple(int(v) for v in pixels[~ok][0])}."
        )
    offsets = np.asarray(offsets, dtype=np.float64)
    if offsets.ndim != 2 or offsets.shape[1] != 4 or not np.all(np.isfinite(offsets)):
        raise ValueError(
            f"The 'offsets' argument of depth_features must be a finite (K, 4) array of "
            f"(u_row, u_col, v_row, v_col). Got shape {offsets.shape} instead."
        )
    if not (np.isfinite(reference_focal) and reference_focal > 0):
        raise ValueError(
            f"The 'reference_focal' parameter of depth_features must be a positive focal "
            f"length in pixels. Got {reference_focal!r} instead."
        )
    return feature_matrix(
        depth,
        mask,
        pixels.astype(np.intp),
        offsets,
        intrinsics,
        reference_focal=reference_focal,
        background=float(background),
    )
