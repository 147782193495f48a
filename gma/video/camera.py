"""The static pinhole camera of a video import.

Assumptions (documented for users in ``gma import video --help``): one camera that does not move or
zoom; square pixels, no skew, no lens distortion; principal point at the image centre. The focal
length comes from the user (``--focal``, pixels) or defaults to the image's longer side — a 53°
field of view across it, between a phone's main camera (~65–70°) and a zoomed-in shot. A wrong focal
length mostly trades against the person's distance, so the 2D fit stays good while the recovered depth
and perspective are off.

World frame: Anny's (Z up, metres). The camera looks along world +Y from behind the person, who faces
−Y (Anny's front) at zero rotation; after the fit the world is shifted so the person's median root
position is the origin.
"""

from __future__ import annotations

import numpy as np

from gma.data.cameras import Cameras

__all__ = ["CAMERA_FROM_WORLD", "default_focal", "intrinsics", "static_camera"]

# OpenCV camera axes (x right, y down, z forward) in Anny's world: x = X, y = −Z, z = +Y.
CAMERA_FROM_WORLD = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)


def default_focal(width: int, height: int) -> float:
    """Focal length in pixels when the user gives none: the longer image side."""
    return float(max(width, height))


def intrinsics(width: int, height: int, focal: float | None = None) -> np.ndarray:
    """K [3, 3]: focal ``focal`` (pixels; default :func:`default_focal`), principal point at the centre
    (pixel (x, y) has its centre at (x + 0.5, y + 0.5), so the centre is (W / 2, H / 2))."""
    f = default_focal(width, height) if focal is None else float(focal)
    if not np.isfinite(f) or f <= 0:
        raise ValueError(f"focal length must be a positive number of pixels, got {focal}")
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], np.float64)


def static_camera(width: int, height: int, K: np.ndarray, centre: np.ndarray) -> Cameras:
    """Cameras of the sequence: ``K`` and a world→camera matrix whose camera sits at world position
    ``centre`` [3] looking along +Y (see the module docstring)."""
    w2c = np.eye(4)
    w2c[:3, :3] = CAMERA_FROM_WORLD
    w2c[:3, 3] = -CAMERA_FROM_WORLD @ np.asarray(centre, np.float64)
    return Cameras(width, height, np.asarray(K, np.float64)[None], w2c[None])
