"""A z-buffered depth and part-label renderer in pure NumPy (no OpenGL).

Triangles of a body mesh at 320 x 240 cover a pixel or a few, so every triangle
is rasterized at once: the pixel centres inside each triangle's clipped bounding
box are enumerated into one flat batch, tested with edge functions, given their
exact depth (inverse depth is linear in the image for a planar triangle, so the
depth is the ray-plane intersection, not an approximation), and resolved by a
scatter-max on inverse depth. Large planes of a room (floor, back wall) are not
rasterized: their depth is the ray-plane intersection computed per pixel.

Pixel convention: the centre of pixel ``(row, column)`` is at image coordinates
``u = column``, ``v = row``, as in :func:`posedrift.camera.backproject`, so a
rendered depth image back-projects onto the surface it came from.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from posedrift._validation import check_points, check_scalar
from posedrift.camera import CameraPose, Intrinsics

# Candidate pixel tests per batch: bounds the temporaries for meshes with large triangles.
_BATCH = 1 << 21
# Edge-function tolerance (in units of barycentric weight): pixel centres exactly on a
# shared edge are then drawn by both triangles rather than by none.
_EDGE_EPS = 1e-9


@dataclass(frozen=True)
class Render:
    """A rendered depth image and its per-pixel part labels.

    Parameters
    ----------
    depth : (H, W) float32
        Depth along the optical axis in metres; 0 where nothing was hit.
    labels : (H, W) uint8
        Part index + 1 (:data:`posedrift.skeleton.PART_NAMES` order) where the mesh
        was hit, 0 for background (empty pixels, floor and wall).
    """

    depth: np.ndarray
    labels: np.ndarray

    def depth_mm(self) -> np.ndarray:
        """Depth as uint16 millimetres (rounded; 0 stays 0, clipped at 65535)."""
        return depth_to_mm(self.depth)

    @property
    def mask(self) -> np.ndarray:
        """``(H, W)`` bool: pixels that show the mesh (the person)."""
        return self.labels > 0


def depth_to_mm(depth: np.ndarray) -> np.ndarray:
    """Metres to uint16 millimetres: rounded, 0 (and NaN) stays 0, clipped at 65535.

    Examples
    --------
    >>> import numpy as np
    >>> depth_to_mm(np.array([0.0, 1.2344, 2.8, 70.0], dtype=np.float32))
    array([    0,  1234,  2800, 65535], dtype=uint16)
    """
    depth = np.asarray(depth, dtype=np.float64)
    mm = np.rint(np.nan_to_num(depth, nan=0.0, posinf=0.0, neginf=0.0) * 1000.0)
    return np.clip(mm, 0, 65535).astype(np.uint16)


@dataclass(frozen=True)
class Scene:
    """A room around the person: a floor plane and a back wall, seen from a camera.

    World frame of the motions (metres, +Y up, the person at x = z = 0 facing +Z at
    frame 0, the camera on the +Z side). Both planes are infinite; the nearer one
    wins, so they meet in a room corner. Their pixels get depth but label 0.

    Parameters
    ----------
    camera : CameraPose
        World-to-camera transform of the rendered frame.
    floor_y : float or None
        Height of the floor plane ``y = floor_y``; None for no floor.
    wall_z : float or None
        The back wall is the plane ``z = wall_z`` (behind the person, so negative);
        None for no wall.
    max_depth : float
        Scene pixels farther than this (metres) stay empty, like a sensor's range.
    """

    camera: CameraPose
    floor_y: float | None = 0.0
    wall_z: float | None = -1.5
    max_depth: float = 8.0

    def __post_init__(self) -> None:
        if not isinstance(self.camera, CameraPose):
            raise ValueError(
                f"The 'camera' of a Scene must be a CameraPose. Got {type(self.camera).__name__}."
            )
        for name in ("floor_y", "wall_z"):
            value = getattr(self, name)
            if value is not None:
                object.__setattr__(self, name, check_scalar(value, name, caller="Scene"))
        object.__setattr__(
            self, "max_depth", check_scalar(self.max_depth, "max_depth", low=0, caller="Scene")
        )

    def planes_camera(self) -> list[tuple[np.ndarray, float]]:
        """The planes in the camera frame as ``(normal (3,), offset)``: ``normal . X = offset``."""
        world = []
        if self.floor_y is not None:
            world.append((np.array([0.0, 1.0, 0.0]), self.floor_y))
        if self.wall_z is not None:
            world.append((np.array([0.0, 0.0, 1.0]), self.wall_z))
        planes = []
        r, t = self.camera.rotation, self.camera.translation
        for normal, offset in world:
            # X_c = R X_w + t  =>  n_w . X_w = o  <=>  (R n_w) . X_c = o + (R n_w) . t
            n_c = r @ normal
            planes.append((n_c, float(offset + n_c @ t)))
        return planes


@lru_cache(maxsize=8)
def _pixel_rays(intrinsics: Intrinsics) -> tuple[np.ndarray, np.ndarray]:
    """Normalized ray directions ``((W,) x/z, (H,) y/z)`` of the pixel centres."""
    k = intrinsics
    rx = (np.arange(k.width) - k.cx) / k.fx
    ry = (np.arange(k.height) - k.cy) / k.fy
    rx.setflags(write=False)
    ry.setflags(write=False)
    return rx, ry


def plane_depth(
    normal: np.ndarray, offset: float, intrinsics: Intrinsics, *, max_depth: float = np.inf
) -> np.ndarray:
    """Per-pixel depth of the infinite plane ``normal . X = offset`` (camera frame, metres).

    The depth of pixel ``(v, u)`` is ``z = offset / (normal . r)`` with the ray
    ``r = ((u - cx) / fx, (v - cy) / fy, 1)``: the exact ray-plane intersection.

    Returns
    -------
    depth : (H, W) float64
        0 where the ray misses the plane, hits it behind the camera, or beyond
        ``max_depth``.

    Examples
    --------
    >>> from posedrift.camera import camera_preset
    >>> d = plane_depth(np.array([0.0, 0.0, 1.0]), 2.5, camera_preset("kinect1-qvga"))
    >>> float(d.min()), float(d.max())
    (2.5, 2.5)
    """
    rx, ry = _pixel_rays(intrinsics)
    n = np.asarray(normal, dtype=float)
    denom = n[0] * rx[None, :] + n[1] * ry[:, None] + n[2]
    with np.errstate(divide="ignore", invalid="ignore"):
        z = offset / denom
    z[~np.isfinite(z) | (z <= 0) | (z > max_depth)] = 0.0
    return z


def _face_setup(
    u: np.ndarray, v: np.ndarray, z: np.ndarray, faces: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, ...]:
    """Per-face bounding boxes and linear forms of two barycentrics and inverse depth.

    Returns only faces whose clipped box holds at least one pixel centre and whose
    projected area is not zero.
    """
    # Column-wise minima: NumPy's reductions along a length-3 axis are slow.
    u0, u1, u2 = u[faces[:, 0]], u[faces[:, 1]], u[faces[:, 2]]
    v0, v1, v2 = v[faces[:, 0]], v[faces[:, 1]], v[faces[:, 2]]
    c0 = np.ceil(np.minimum(np.minimum(u0, u1), u2))
    c1 = np.floor(np.maximum(np.maximum(u0, u1), u2))
    r0 = np.ceil(np.minimum(np.minimum(v0, v1), v2))
    r1 = np.floor(np.maximum(np.maximum(v0, v1), v2))
    np.clip(c0, 0, width - 1, out=c0)
    np.clip(c1, -1, width - 1, out=c1)
    np.clip(r0, 0, height - 1, out=r0)
    np.clip(r1, -1, height - 1, out=r1)
    # w0 = (a0 u + b0 v + k0) / den, w1 = (a1 u + b1 v + k1) / den, w2 = 1 - w0 - w1.
    a0 = v1 - v2
    b0 = u2 - u1
    k0 = u1 * v2 - u2 * v1
    a1 = v2 - v0
    b1 = u0 - u2
    k1 = u2 * v0 - u0 * v2
    den = a0 * u0 + b0 * v0 + k0
    keep = (c1 >= c0) & (r1 >= r0) & (np.abs(den) > 1e-12)
    idx = np.flatnonzero(keep)
    inv = 1.0 / den[idx]
    a0, b0, k0 = a0[idx] * inv, b0[idx] * inv, k0[idx] * inv
    a1, b1, k1 = a1[idx] * inv, b1[idx] * inv, k1[idx] * inv
    # Inverse depth q = w0/z0 + w1/z1 + w2/z2 is exact (linear in the image) for a plane.
    fk = faces[idx]
    iz0, iz1, iz2 = 1.0 / z[fk[:, 0]], 1.0 / z[fk[:, 1]], 1.0 / z[fk[:, 2]]
    d0 = iz0 - iz2
    d1 = iz1 - iz2
    qa = a0 * d0 + a1 * d1
    qb = b0 * d0 + b1 * d1
    qk = k0 * d0 + k1 * d1 + iz2
    c0 = c0[idx].astype(np.int64)
    r0 = r0[idx].astype(np.int64)
    bw = c1[idx].astype(np.int64) - c0 + 1
    bh = r1[idx].astype(np.int64) - r0 + 1
    return idx, c0, r0, bw, bh, np.stack([a0, b0, k0, a1, b1, k1, qa, qb, qk])


def _rasterize(
    u: np.ndarray, v: np.ndarray, z: np.ndarray, faces: np.ndarray, width: int, height: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Z-buffer the triangles.

    Returns
    -------
    inv_depth : (H * W,) float64
        Largest inverse depth per pixel, 0 where no triangle covers the pixel.
    pixels : (K,) int64
        Flat indices of the covered pixels (each once).
    face : (K,) int64
        The winning face of each covered pixel (an index into ``faces``).
    corner : (K,) int64
        Which of its three vertices has the largest barycentric weight there.
    """
    idx, c0, r0, bw, bh, coef = _face_setup(u, v, z, faces, width, height)
    inv_depth = np.zeros(width * height)
    n = bw * bh
    ends = np.cumsum(n)
    total = int(ends[-1]) if len(ends) else 0
    cand_pix, cand_face, cand_q, cand_w = [], [], [], []
    start_face = 0
    while start_face < len(idx):
        # Faces whose candidates fit in one batch (at least one face).
        base = int(ends[start_face - 1]) if start_face else 0
        stop = int(np.searchsorted(ends, base + _BATCH, side="right"))
        stop = max(stop, start_face + 1)
        sl = slice(start_face, stop)
        counts = n[sl]
        m = int(counts.sum())
        owner = np.repeat(np.arange(start_face, stop), counts)
        first = np.repeat(ends[sl] - counts - base, counts)
        local = np.arange(m) - first
        w_box = bw[owner]
        row, col = np.divmod(local, w_box)
        row += r0[owner]
        col += c0[owner]
        cf = coef[:, owner]  # (9, m), rows contiguous
        uu = col.astype(np.float64)
        vv = row.astype(np.float64)
        w0 = cf[0] * uu + cf[1] * vv + cf[2]
        w1 = cf[3] * uu + cf[4] * vv + cf[5]
        w2 = 1.0 - w0 - w1
        inside = (w0 >= -_EDGE_EPS) & (w1 >= -_EDGE_EPS) & (w2 >= -_EDGE_EPS)
        q = cf[6] * uu + cf[7] * vv + cf[8]
        inside &= q > 0
        sel = np.flatnonzero(inside)
        cand_pix.append(row[sel] * width + col[sel])
        cand_face.append(owner[sel])
        cand_q.append(q[sel])
        cand_w.append(np.stack([w0[sel], w1[sel]]))
        start_face = stop
    if total == 0:
        empty = np.zeros(0, dtype=np.int64)
        return inv_depth, empty, empty, empty
    pix = np.concatenate(cand_pix)
    face = np.concatenate(cand_face)
    q = np.concatenate(cand_q)
    weights = np.concatenate(cand_w, axis=1)
    np.maximum.at(inv_depth, pix, q)
    win = np.flatnonzero(q == inv_depth[pix])
    # Ties (a pixel centre on a shared edge) keep one winner per pixel.
    pix_w, first = np.unique(pix[win], return_index=True)
    win = win[first]
    w0, w1 = weights[:, win]
    w2 = 1.0 - w0 - w1
    corner = np.where((w0 >= w1) & (w0 >= w2), 0, np.where(w1 >= w2, 1, 2))
    return inv_depth, pix_w, idx[face[win]], corner


def render(
    vertices: np.ndarray,
    faces: np.ndarray,
    intrinsics: Intrinsics,
    *,
    vertex_parts: np.ndarray | None = None,
    scene: Scene | None = None,
    cull_backfaces: bool = False,
    near: float = 0.05,
) -> Render:
    """Render a triangle mesh into a depth image and a part-label image.

    Parameters
    ----------
    vertices : (V, 3) float
        Vertex positions in the camera frame, metres (+X right, +Y down, +Z forward).
    faces : (F, 3) int
        Vertex indices of each triangle.
    intrinsics : Intrinsics
        The pinhole camera; sets the image size.
    vertex_parts : (V,) int, optional
        Part index (0..14) of each vertex. A pixel takes the part of the vertex of its
        triangle with the largest barycentric weight. Without it, every mesh pixel is
        labelled 1 (part 0).
    scene : Scene, optional
        Floor and back wall behind the mesh (depth, label 0).
    cull_backfaces : bool
        Skip triangles facing away from the camera (counter-clockwise winding seen
        from outside is taken as the front). Only for closed, consistently wound meshes.
    near : float
        Triangles with a vertex nearer than this (metres) are dropped.

    Returns
    -------
    Render
        ``depth`` (H, W) float32 metres (0 empty) and ``labels`` (H, W) uint8.

    Raises
    ------
    ValueError
        If the arrays have the wrong shapes, a face indexes a missing vertex, or a
        part index is outside 0..254.

    Examples
    --------
    >>> import numpy as np
    >>> from posedrift.camera import Intrinsics
    >>> k = Intrinsics(fx=100, fy=100, cx=20, cy=15, width=40, height=30)
    >>> square = np.array([[-0.1, -0.1, 2.0], [0.1, -0.1, 2.0], [0.1, 0.1, 2.0], [-0.1, 0.1, 2.0]])
    >>> out = render(square, np.array([[0, 1, 2], [0, 2, 3]]), k)
    >>> float(out.depth.max()), int(out.mask.sum())
    (2.0, 121)
    """
    if not isinstance(intrinsics, Intrinsics):
        raise ValueError(
            f"The 'intrinsics' argument of render must be an Intrinsics. "
            f"Got {type(intrinsics).__name__} instead."
        )
    vertices = check_points(vertices, "vertices", caller="render", min_points=0)
    faces = _check_faces(faces, len(vertices))
    near = check_scalar(near, "near", low=0, caller="render")
    parts = None
    if vertex_parts is not None:
        parts = np.asarray(vertex_parts)
        if parts.shape != (len(vertices),) or not np.issubdtype(parts.dtype, np.integer):
            raise ValueError(
                f"The 'vertex_parts' argument of render must be ({len(vertices)},) integers, "
                f"one per vertex. Got shape {parts.shape} and dtype {parts.dtype} instead."
            )
        if len(parts) and (parts.min() < 0 or parts.max() > 254):
            raise ValueError(
                f"The 'vertex_parts' argument of render must hold part indices in [0, 254]. "
                f"Got values in [{parts.min()}, {parts.max()}] instead."
            )
    if scene is not None and not isinstance(scene, Scene):
        raise ValueError(
            f"The 'scene' argument of render must be a Scene or None. "
            f"Got {type(scene).__name__} instead."
        )
    k = intrinsics
    h, w = k.height, k.width
    z = vertices[:, 2]
    if len(faces):
        front = z > near
        keep = front[faces[:, 0]] & front[faces[:, 1]] & front[faces[:, 2]]
        if cull_backfaces:
            p0, p1, p2 = (vertices[faces[:, i]] for i in range(3))
            normal = np.cross(p1 - p0, p2 - p0)
            keep &= np.einsum("ij,ij->i", normal, p0) < 0
        faces = faces[keep] if not keep.all() else faces
    with np.errstate(divide="ignore", invalid="ignore"):
        u = k.fx * vertices[:, 0] / z + k.cx
        v = k.fy * vertices[:, 1] / z + k.cy
    inv_depth, pix, face, corner = _rasterize(u, v, z, faces, w, h)
    depth = np.zeros(h * w)
    depth[pix] = 1.0 / inv_depth[pix]
    labels = np.zeros(h * w, dtype=np.uint8)
    if parts is None:
        labels[pix] = 1
    else:
        labels[pix] = parts[faces[face, corner]].astype(np.uint8) + 1
    depth = depth.reshape(h, w)
    labels = labels.reshape(h, w)
    if scene is not None:
        for normal, offset in scene.planes_camera():
            pd = plane_depth(normal, offset, k, max_depth=scene.max_depth)
            take = (pd > 0) & ((depth == 0) | (pd < depth))
            depth[take] = pd[take]
            labels[take] = 0
    return Render(depth=depth.astype(np.float32), labels=labels)


def _check_faces(faces: np.ndarray, n_vertices: int) -> np.ndarray:
    arr = np.asarray(faces)
    if arr.ndim != 2 or arr.shape[1] != 3 or not np.issubdtype(arr.dtype, np.integer):
        if not (arr.size == 0 and arr.ndim <= 2):
            raise ValueError(
                f"The 'faces' argument of render must be an (F, 3) integer array. "
                f"Got shape {arr.shape} and dtype {arr.dtype} instead."
            )
        return np.zeros((0, 3), dtype=np.int64)
    if len(arr) and (arr.min() < 0 or arr.max() >= n_vertices):
        raise ValueError(
            f"The 'faces' argument of render must index the {n_vertices} vertices "
            f"(0..{n_vertices - 1}). Got indices in [{arr.min()}, {arr.max()}] instead."
        )
    return arr.astype(np.int64, copy=False)
