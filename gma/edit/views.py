"""Where an edit is seen from: the avatar's morphed mesh in a pose, and named cameras around it.

Screen-space tools (box, lasso, brush, wand, stamp) take a camera and the posed vertices of the avatar's
*morphed* mesh (body rest shape + mesh-layer offsets, skinned), so a selection follows what the render
shows. Named views look at the avatar in its canonical (editing) pose from the front, back, left or
right — "left" is the avatar's own left side.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from gma.core.camera import Camera
from gma.edit.errors import EditError
from gma.edit.limits import VIEW_SIZE, check_number

__all__ = ["NAMED_VIEWS", "canonical_vertices", "named_view", "posed_vertices"]

NAMED_VIEWS = ("front", "back", "left", "right")
# The body faces -y when z is up (Anny), +z when y is up (SMPL-X): the viewer's orbit convention.
_UP = {"y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}
_FRONT = {"y": np.array([0.0, 0.0, 1.0]), "z": np.array([0.0, -1.0, 0.0])}


@torch.no_grad()
def posed_vertices(body, vertex_offsets: torch.Tensor, params: dict) -> torch.Tensor:
    """[V, 3] the morphed mesh (rest vertices of ``params``' shape and expression + ``vertex_offsets``
    [V, 3]) skinned into ``params``' pose."""
    from gma.body.skinning import linear_blend_skinning

    params = body.check_params(params)
    rest = body.rest_vertices(params) + vertex_offsets
    return linear_blend_skinning(rest, body.skin_indices, body.skin_weights, body.bone_transforms(params))


def canonical_vertices(body, vertex_offsets: torch.Tensor, shape: torch.Tensor) -> torch.Tensor:
    """[V, 3] the morphed mesh in the canonical editing pose for body ``shape``."""
    return posed_vertices(body, vertex_offsets, body.canonical_params(shape))


def named_view(name: str, vertices, up_axis: str = "z", width: int = 512, height: int = 512,
               fov_y_deg: float = 40.0) -> Camera:
    """A camera looking at the centre of ``vertices`` [V, 3] from ``name`` (front, back, left, right),
    framing the whole body with a 10 % margin."""
    if name not in NAMED_VIEWS:
        raise EditError(f"unknown view {name!r}; known: {', '.join(NAMED_VIEWS)}")
    for side in (width, height):
        check_number("view size", side, *VIEW_SIZE, "px")
    v = np.asarray(vertices, np.float64)
    lo, hi = v.min(0), v.max(0)
    up, front = _UP[up_axis], _FRONT[up_axis]
    left = np.cross(up, front)  # the subject's own left: up x forward for a right-handed world
    direction = {"front": front, "back": -front, "left": left, "right": -left}[name]
    centre = 0.5 * (lo + hi)
    ext = hi - lo
    half_h = 0.5 * float(ext @ np.abs(up))
    half_w = 0.5 * float(np.max(ext * (1 - np.abs(up)) * (1 - np.abs(direction))))
    aspect = width / height
    tan = math.tan(math.radians(fov_y_deg) / 2)
    depth = 0.5 * float(ext @ np.abs(direction))
    distance = 1.1 * max(half_h / tan, half_w / (tan * aspect)) + depth
    return Camera.look_at(centre + distance * direction, centre, up=tuple(up), fov_y_deg=fov_y_deg,
                          width=width, height=height)
