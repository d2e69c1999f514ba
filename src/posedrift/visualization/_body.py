"""The posed 3-D body (the paper's Fig. 7c): the body model on recovered joints, rendered."""

from __future__ import annotations

import numpy as np

from posedrift.camera import Intrinsics

_FLIP = np.array([1.0, -1.0, -1.0])  # camera frame <-> a Y-up frame (180 degrees about X)


def render_posed_body(
    joints: np.ndarray,
    intrinsics: Intrinsics,
    *,
    body: object | None = None,
    shade: bool = True,
) -> np.ndarray:
    """Pose the body model on camera-frame joints and render it, coloured by part.

    Parameters
    ----------
    joints : (15, 3) float
        Recovered joints, camera frame, metres (all finite).
    intrinsics : Intrinsics
        The camera to render with (the input's, so the body overlays the depth).
    body : synthetic.BodyModel, optional
        Defaults to ``BodyModel.load_default()``.
    shade : bool
        Darken parts with depth so that overlapping limbs stay distinguishable.

    Returns
    -------
    (H, W, 3) uint8
        Part colours on black.

    Raises
    ------
    ValueError
        If a joint is unknown.
    """
    from posedrift.synthetic import BodyModel, render
    from posedrift.visualization._draw import draw_label_image

    joints = np.asarray(joints, dtype=float)
    if joints.shape != (15, 3) or not np.isfinite(joints).all():
        raise ValueError(
            "render_posed_body needs 15 known joints (15, 3), camera frame, metres. "
            f"Got shape {joints.shape} with {int((~np.isfinite(joints)).any(-1).sum())} unknown."
        )
    if body is None:
        body = BodyModel.load_default()
    vertices = body.pose(joints * _FLIP) * _FLIP
    out = render(vertices, body.faces, intrinsics, vertex_parts=body.vertex_parts)
    image = draw_label_image(out.labels)
    if shade and out.mask.any():
        depth = out.depth[out.mask]
        lo, hi = float(depth.min()), float(depth.max())
        factor = 1.0 - 0.45 * (out.depth - lo) / max(hi - lo, 1e-6)
        image = np.where(
            out.mask[..., None], (image * np.clip(factor, 0.5, 1.0)[..., None]), image
        ).astype(np.uint8)
    return image
