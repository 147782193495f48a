"""numpy mirrors of the WGSL structs in ``shaders/wgsl/common/render_types.wgsl``.

tests/test_render_layouts.py round-trips these through a shader to prove the layouts agree.
"""

from __future__ import annotations

import numpy as np

TILE_SIZE = 16
ALPHA_THRESHOLD = 1.0 / 255.0
MAX_ALPHA = 0.999
TRANSMITTANCE_EPS = 1e-4
NEAR_PLANE = 0.01

RENDER_PARAMS = np.dtype(
    [
        ("w2c", "<f4", (3, 4)),        # rows of [R | t]
        ("k", "<f4", (3, 4)),          # rows of K, 4th column unused
        ("image_size", "<u4", (2,)),
        ("tile_grid", "<u4", (2,)),
        ("num_surfels", "<u4"),
        ("isect_capacity", "<u4"),
        ("num_channels", "<u4"),
        ("reserved", "<u4"),
    ]
)
assert RENDER_PARAMS.itemsize == 128

PROJECTED_SURFEL = np.dtype(
    [
        ("p_ref", "<f4", (4,)),         # ray-splat intersection at the reference point c, c.x
        ("dp_dx", "<f4", (4,)),         # its change per pixel in x, c.y
        ("dp_dy", "<f4", (4,)),         # its change per pixel in y, opacity
        ("normal_depth", "<f4", (4,)),  # camera-space normal, depth
    ]
)
assert PROJECTED_SURFEL.itemsize == 64

DISPATCH_INFO = np.dtype([("groups", "<u4", (3,)), ("count", "<u4")])
assert DISPATCH_INFO.itemsize == 16


def tile_grid(width: int, height: int) -> tuple[int, int]:
    return (width + TILE_SIZE - 1) // TILE_SIZE, (height + TILE_SIZE - 1) // TILE_SIZE


def render_params(viewmat: np.ndarray, K: np.ndarray, width: int, height: int, num_surfels: int,
                  isect_capacity: int, channels: int) -> np.ndarray:
    """Pack one ``RenderParams`` uniform. ``viewmat`` [4, 4] world->camera, ``K`` [3, 3]."""
    p = np.zeros((), RENDER_PARAMS)
    p["w2c"] = np.asarray(viewmat, np.float32)[:3, :4]
    p["k"][:, :3] = np.asarray(K, np.float32)
    p["image_size"] = (width, height)
    p["tile_grid"] = tile_grid(width, height)
    p["num_surfels"] = num_surfels
    p["isect_capacity"] = isect_capacity
    p["num_channels"] = channels
    return p
