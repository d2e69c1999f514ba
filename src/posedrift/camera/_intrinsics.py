"""Pinhole intrinsics, named camera presets, and camera poses.

Camera frame (used everywhere inside posedrift): metres, right-handed, +X to the
image's right, +Y down the image, +Z along the optical axis (OpenCV's convention).
"""

from __future__ import annotations

from dataclasses import dataclass
from types import MappingProxyType

import numpy as np

from posedrift._validation import check_points


@dataclass(frozen=True)
class Intrinsics:
    """Pinhole intrinsics of a depth camera.

    Parameters
    ----------
    fx, fy : float
        Focal lengths in pixels.
    cx, cy : float
        Principal point in pixels (column, row), inside the image.
    width, height : int
        Image size in pixels.

    Raises
    ------
    ValueError
        If a focal length is not positive, the size is not positive, or the
        principal point lies outside the image.
    """

    fx: float
    fy: float
    cx: float
    cy: float
    width: int
    height: int

    def __post_init__(self) -> None:
        for name in ("fx", "fy"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0):
                raise ValueError(
                    f"The '{name}' intrinsic must be a positive focal length in pixels. "
                    f"Got {value!r} instead."
                )
        for name in ("width", "height"):
            value = getattr(self, name)
            if int(value) != value or value <= 0:
                raise ValueError(
                    f"The '{name}' intrinsic must be a positive whole number of pixels. "
                    f"Got {value!r} instead."
                )
            object.__setattr__(self, name, int(value))
        for name, limit in (("cx", self.width), ("cy", self.height)):
            value = getattr(self, name)
            if not (np.isfinite(value) and 0 <= value <= limit):
                raise ValueError(
                    f"The '{name}' intrinsic (principal point) must lie inside the image, "
                    f"in [0, {limit}]. Got {value!r} instead."
                )
        for name in ("fx", "fy", "cx", "cy"):
            object.__setattr__(self, name, float(getattr(self, name)))

    @property
    def shape(self) -> tuple[int, int]:
        """Image shape ``(height, width)``, as NumPy orders it."""
        return (self.height, self.width)

    def scaled(self, factor: float) -> Intrinsics:
        """The same camera at ``factor`` times the resolution."""
        return Intrinsics(
            fx=self.fx * factor,
            fy=self.fy * factor,
            cx=self.cx * factor,
            cy=self.cy * factor,
            width=round(self.width * factor),
            height=round(self.height * factor),
        )

    def to_dict(self) -> dict[str, float | int]:
        """As the ``intrinsics`` object of the product's JSON files."""
        return {
            "fx": self.fx,
            "fy": self.fy,
            "cx": self.cx,
            "cy": self.cy,
            "width": self.width,
            "height": self.height,
        }

    @classmethod
    def from_dict(cls, data: dict) -> Intrinsics:
        """Inverse of :meth:`to_dict`."""
        missing = [k for k in ("fx", "fy", "cx", "cy", "width", "height") if k not in data]
        if missing:
            raise ValueError(f"Intrinsics are missing the field(s) {missing}. Got {sorted(data)}.")
        return cls(**{k: data[k] for k in ("fx", "fy", "cx", "cy", "width", "height")})


CAMERA_PRESETS = MappingProxyType(
    {
        # Kinect v1 depth, nominal (the UTD-MHAD and paper setting at QVGA).
        "kinect1-vga": Intrinsics(fx=571.26, fy=571.26, cx=320.0, cy=240.0, width=640, height=480),
        "kinect1-qvga": Intrinsics(fx=285.63, fy=285.63, cx=160.0, cy=120.0, width=320, height=240),
        # Kinect v2 (Xbox One) depth, typical factory values.
        "kinect2": Intrinsics(
            fx=365.456, fy=365.456, cx=254.878, cy=205.395, width=512, height=424
        ),
        # Intel RealSense D435 depth at 640 x 480, typical factory values.
        "d435": Intrinsics(fx=385.0, fy=385.0, cx=320.0, cy=240.0, width=640, height=480),
    }
)
"""Named nominal intrinsics. A calibrated camera's own values are always better."""


def camera_preset(name: str) -> Intrinsics:
    """The intrinsics of a named camera preset.

    Raises
    ------
    ValueError
        If ``name`` is unknown; the message lists the valid names.
    """
    try:
        return CAMERA_PRESETS[name]
    except KeyError:
        raise ValueError(
            f"Unknown camera preset {name!r}. Valid presets: {', '.join(CAMERA_PRESETS)}."
        ) from None


def parse_intrinsics(text: str, *, width: int, height: int) -> Intrinsics:
    """Parse ``"fx,fy,cx,cy"`` (the ``--intrinsics`` option) for an image size."""
    parts = [p for p in text.replace(" ", "").split(",") if p]
    try:
        values = [float(p) for p in parts]
    except ValueError:
        values = []
    if len(values) != 4:
        raise ValueError(f"--intrinsics must be four numbers 'fx,fy,cx,cy'. Got {text!r} instead.")
    fx, fy, cx, cy = values
    return Intrinsics(fx=fx, fy=fy, cx=cx, cy=cy, width=width, height=height)


@dataclass(frozen=True)
class CameraPose:
    """A rigid world-to-camera transform: ``x_camera = rotation @ x_world + translation``.

    Parameters
    ----------
    rotation : (3, 3) float
        A proper rotation matrix.
    translation : (3,) float
        In metres.
    """

    rotation: np.ndarray
    translation: np.ndarray

    def __post_init__(self) -> None:
        rotation = np.asarray(self.rotation, dtype=float)
        translation = np.asarray(self.translation, dtype=float).reshape(-1)
        if rotation.shape != (3, 3) or not np.allclose(rotation @ rotation.T, np.eye(3), atol=1e-6):
            raise ValueError(
                f"The 'rotation' of a CameraPose must be a 3 x 3 rotation matrix. Got {rotation!r}."
            )
        if translation.shape != (3,):
            raise ValueError(
                f"The 'translation' of a CameraPose must have 3 values. Got {translation.shape}."
            )
        object.__setattr__(self, "rotation", rotation)
        object.__setattr__(self, "translation", translation)

    @classmethod
    def look_at(
        cls,
        eye: np.ndarray,
        target: np.ndarray,
        up: np.ndarray = (0.0, 1.0, 0.0),
    ) -> CameraPose:
        """A camera at ``eye`` (world, metres) looking at ``target`` with ``up`` up in the image."""
        eye = np.asarray(eye, dtype=float)
        forward = np.asarray(target, dtype=float) - eye
        forward /= np.linalg.norm(forward)
        right = np.cross(forward, np.asarray(up, dtype=float))
        if np.linalg.norm(right) < 1e-9:
            raise ValueError("The 'up' vector of CameraPose.look_at is parallel to the view.")
        right /= np.linalg.norm(right)
        down = np.cross(forward, right)
        rotation = np.stack([right, down, forward])
        return cls(rotation=rotation, translation=-rotation @ eye)

    def world_to_camera(self, points: np.ndarray) -> np.ndarray:
        """Map ``(..., 3)`` world points into the camera frame."""
        return np.asarray(points, dtype=float) @ self.rotation.T + self.translation

    def camera_to_world(self, points: np.ndarray) -> np.ndarray:
        """Map ``(..., 3)`` camera points into the world frame."""
        return (np.asarray(points, dtype=float) - self.translation) @ self.rotation


def backproject(
    depth: np.ndarray, intrinsics: Intrinsics, mask: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1 of the paper with an explicit principal point.

    ``X = (u - cx) Z / fx``, ``Y = (v - cy) Z / fy``, ``Z = D``.

    Parameters
    ----------
    depth : (H, W) float
        Depth in metres; 0 or NaN marks no measurement.
    intrinsics : Intrinsics
    mask : (H, W) bool, optional
        Pixels to keep (in addition to valid depth).

    Returns
    -------
    points : (N, 3) float
        Camera-frame points in metres.
    pixels : (N, 2) int
        ``(row, column)`` of each point.
    """
    depth = np.asarray(depth)
    if depth.shape != intrinsics.shape:
        raise ValueError(
            f"The 'depth' image must have the intrinsics' shape {intrinsics.shape}. "
            f"Got {depth.shape} instead."
        )
    valid = np.isfinite(depth) & (depth > 0)
    if mask is not None:
        valid &= np.asarray(mask, dtype=bool)
    # Flat indices split into (row, column): about twice as fast as a 2-D np.nonzero.
    flat = np.flatnonzero(valid)
    rows, cols = np.divmod(flat, depth.shape[1])
    z = depth.reshape(-1)[flat].astype(float)
    x = (cols - intrinsics.cx) * z / intrinsics.fx
    y = (rows - intrinsics.cy) * z / intrinsics.fy
    return np.column_stack([x, y, z]), np.column_stack([rows, cols])


def project(points: np.ndarray, intrinsics: Intrinsics) -> np.ndarray:
    """Project camera-frame points to ``(N, 2)`` pixel coordinates ``(u, v)`` (column, row)."""
    points = check_points(points, "points", caller="project", min_points=0)
    z = points[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        u = intrinsics.fx * points[:, 0] / z + intrinsics.cx
        v = intrinsics.fy * points[:, 1] / z + intrinsics.cy
    return np.column_stack([u, v])
