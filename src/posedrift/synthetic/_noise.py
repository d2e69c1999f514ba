"""A Kinect v1-like depth noise model for synthetic frames.

Kinect v1 measures disparity against a projected speckle pattern and reports
depth ``z = b f / d``; what that does to a clean depth image:

- **Axial noise growing with z squared.** Khoshelham & Elberink (2012) measured
  the random depth error as ``sigma_z = 1.425e-3 z^2`` (metres), about 1.4 mm at
  1 m, 11 mm at 2.8 m and 3.6 cm at 5 m. Because ``sigma_z = z^2 sigma_d / (b f)``,
  the model adds Gaussian noise of ``sigma_d = 1.425e-3 b f`` pixels to the
  disparity, which gives exactly that law.
- **Depth quantization.** Disparity is measured in 1/8 pixel steps of the
  sensor's full-resolution IR camera (focal length about 580 px, baseline
  7.5 cm; Khoshelham & Elberink 2012, Smisek et al. 2011), so depth comes in steps
  of ``z^2 / (8 b f)``: about 2.2 cm at 2.8 m and 7 cm at 5 m, as both papers report.
- **Missing pixels at silhouette edges.** The block matcher fails where its window
  straddles a depth discontinuity, and the projector's offset shadows one side of
  every foreground object (Khoshelham & Elberink 2012, Fig. 5; Nguyen et al. 2012
  measured a lateral error of about 1 px at the edges). Pixels next to a
  discontinuity are dropped with a probability.
- **A few random holes**, as specular or dark surfaces give.
- **Range limits.** Nothing nearer than ``min_depth`` or beyond ``max_depth``.

References
----------
K. Khoshelham and S. O. Elberink, "Accuracy and resolution of Kinect depth data
for indoor mapping applications", Sensors 12(2), 2012. doi:10.3390/s120201437

C. V. Nguyen, S. Izadi and D. Lovell, "Modeling Kinect sensor noise for improved
3D reconstruction and tracking", 3DIMPVT 2012. doi:10.1109/3DIMPVT.2012.84

J. Smisek, M. Jancosek and T. Pajdla, "3D with Kinect", ICCV Workshops 2011.
doi:10.1109/ICCVW.2011.6130380
"""

from __future__ import annotations

import numpy as np

from posedrift._validation import check_rng, check_scalar


def kinect_noise(
    depth: np.ndarray,
    *,
    rng: int | np.random.Generator | None = None,
    sigma_coefficient: float = 1.425e-3,
    baseline: float = 0.075,
    disparity_focal: float = 580.0,
    subpixel: int = 8,
    edge_threshold: float = 0.05,
    edge_dropout: float = 0.5,
    hole_rate: float = 0.002,
    min_depth: float = 0.5,
    max_depth: float = 8.0,
) -> np.ndarray:
    """Degrade a clean depth image the way a Kinect v1 would.

    Parameters
    ----------
    depth : (H, W) float
        Clean depth in metres; 0 marks no measurement.
    rng : int, numpy.random.Generator or None
        Seed or generator.
    sigma_coefficient : float
        ``c`` in ``sigma_z = c z^2`` (metres, z in metres); Khoshelham & Elberink
        (2012). 0 disables the random noise (quantization stays).
    baseline : float
        Projector-camera baseline ``b`` in metres (Kinect v1: 0.075).
    disparity_focal : float
        Focal length ``f`` in pixels of the camera the disparity is measured in (the
        Kinect v1 IR camera at 640 x 480: about 580), independent of the output's.
    subpixel : int
        Disparity steps per pixel (Kinect v1: 8); 0 disables quantization.
    edge_threshold : float
        A pixel is on a depth discontinuity when a 4-neighbour is empty or differs by
        more than this (metres).
    edge_dropout : float
        Probability in [0, 1] that a pixel on a discontinuity is lost.
    hole_rate : float
        Probability in [0, 1] that any other valid pixel is lost.
    min_depth, max_depth : float
        Measurable range in metres; depth outside it reads 0.

    Returns
    -------
    depth : (H, W) float32
        Noisy depth in metres, 0 where missing. The input is not modified.

    Examples
    --------
    >>> import numpy as np
    >>> clean = np.full((40, 40), 2.8, dtype=np.float32)
    >>> noisy = kinect_noise(clean, rng=0, edge_dropout=0.0, hole_rate=0.0)
    >>> bool(abs(float(np.median(noisy)) - 2.8) < 0.02), len(np.unique(noisy)) < 10
    (True, True)
    """
    where = "kinect_noise"
    depth = np.asarray(depth)
    if depth.ndim != 2 or not np.issubdtype(depth.dtype, np.number):
        raise ValueError(
            f"The 'depth' argument of {where} must be a 2-D numeric image. "
            f"Got shape {depth.shape} and dtype {depth.dtype} instead."
        )
    gen = check_rng(rng)
    c = check_scalar(sigma_coefficient, "sigma_coefficient", low=0, include_low=True, caller=where)
    b = check_scalar(baseline, "baseline", low=0, caller=where)
    f = check_scalar(disparity_focal, "disparity_focal", low=0, caller=where)
    steps = check_scalar(subpixel, "subpixel", low=0, include_low=True, integer=True, caller=where)
    threshold = check_scalar(edge_threshold, "edge_threshold", low=0, caller=where)
    p_edge = check_scalar(
        edge_dropout,
        "edge_dropout",
        low=0,
        high=1,
        include_low=True,
        include_high=True,
        caller=where,
    )
    p_hole = check_scalar(
        hole_rate, "hole_rate", low=0, high=1, include_low=True, include_high=True, caller=where
    )
    lo = check_scalar(min_depth, "min_depth", low=0, include_low=True, caller=where)
    hi = check_scalar(max_depth, "max_depth", low=lo, caller=where)

    z = np.nan_to_num(depth.astype(np.float64), nan=0.0, posinf=0.0, neginf=0.0)
    valid = (z >= lo) & (z <= hi) & (z > 0)
    edge = _discontinuities(np.where(valid, z, 0.0), threshold)

    out = np.zeros(z.shape)
    bf = b * f
    zv = z[valid]
    disparity = bf / zv
    if c > 0:
        disparity = disparity + gen.normal(0.0, c * bf, size=disparity.shape)
    if steps > 0:
        disparity = np.round(disparity * steps) / steps
    with np.errstate(divide="ignore"):
        noisy = np.where(disparity > 0, bf / np.maximum(disparity, 1e-12), 0.0)
    noisy[(noisy < lo) | (noisy > hi)] = 0.0
    out[valid] = noisy

    drop = gen.random(z.shape)
    lost = np.where(edge, drop < p_edge, drop < p_hole)
    out[lost] = 0.0
    return out.astype(np.float32)


def _discontinuities(depth: np.ndarray, threshold: float) -> np.ndarray:
    """Valid pixels with a 4-neighbour that is empty or differs by more than ``threshold``."""
    valid = depth > 0
    edge = np.zeros(depth.shape, dtype=bool)
    for axis in (0, 1):
        a = np.moveaxis(depth, axis, 0)
        jump = (np.abs(a[1:] - a[:-1]) > threshold) | (a[1:] == 0) | (a[:-1] == 0)
        e = np.moveaxis(edge, axis, 0)
        e[1:] |= jump
        e[:-1] |= jump
    return edge & valid
