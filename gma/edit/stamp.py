"""Stamp: project an image (RGBA, or a solid shape) onto the avatar from a view, then paint.

Every surfel of the candidate faces is placed in the view's pose and projected; one that lies at the
visible depth of the face-ID render (within the surfel layer's thickness) and under the image gets the
image colour as its paint target, weighted by the image alpha (and the selection's soft weight).
Surfels behind the visible surface get weight 0; faces none of whose surfels are hit are not touched at
all, so everything hidden from the stamping view stays bit-identical.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gma.edit.errors import EditError
from gma.edit.limits import MAX_ROTATION_DEG, MAX_SCREEN_PIXELS, MAX_STAMP_METRES, check_number, check_pixel
from gma.edit.screen import ScreenView

__all__ = ["SHAPES", "StampPlacement", "load_stamp_image", "resolve_placement", "solid_shape", "stamp_targets"]

SHAPES = ("circle", "square", "ring")


@dataclass
class StampPlacement:
    """Where the image goes in the view: ``centre`` (x, y) pixels (None: the centroid of the visible
    selected faces, or the image centre without a selection), ``size`` of the image's longer side in
    ``unit`` "m" (on the body, at the centre's depth) or "px", and ``rotation`` in degrees
    (counter-clockwise on screen)."""

    centre: tuple[float, float] | None = None
    size: float = 0.15
    unit: str = "m"
    rotation: float = 0.0

    def __post_init__(self):
        if self.unit not in ("m", "px"):
            raise EditError(f"stamp size unit must be 'm' or 'px', got {self.unit!r}")
        self.size = check_stamp_size("stamp size", self.size, self.unit)
        self.rotation = check_number("stamp rotation", self.rotation, -MAX_ROTATION_DEG, MAX_ROTATION_DEG,
                                     "degrees")
        if self.centre is not None:
            self.centre = check_pixel("stamp centre", self.centre)

    @staticmethod
    def parse_size(text: str, name: str = "stamp size") -> tuple[float, str]:
        """``0.15m``, ``15cm`` or ``120px`` -> (size, unit), checked against the unit's range; errors
        name ``name`` (the option the text came from)."""
        s = text.strip().lower()
        for suffix, unit, mult in (("cm", "m", 0.01), ("mm", "m", 0.001), ("px", "px", 1.0), ("m", "m", 1.0)):
            if s.endswith(suffix):
                try:
                    value = float(s[: -len(suffix)]) * mult
                except ValueError:
                    break
                return check_stamp_size(f"{name} {text}", value, unit), unit
        raise EditError(f"cannot parse {name} {text!r}: use e.g. 0.15m, 15cm or 120px")


def check_stamp_size(name: str, size: float, unit: str) -> float:
    """``size`` in ``unit`` ("m" or "px") when it is finite, positive and at most MAX_STAMP_METRES /
    MAX_SCREEN_PIXELS, else EditError naming ``name`` and the range."""
    high = MAX_STAMP_METRES if unit == "m" else MAX_SCREEN_PIXELS
    return check_number(name, size, 0.0, high, unit, low_open=True)


def load_stamp_image(path) -> np.ndarray:
    """[h, w, 4] float32 RGBA in [0, 1] from an image file (alpha 1 where the file has none)."""
    from gma.core.images import read_image

    path = Path(path)
    if not path.is_file():
        raise EditError(f"stamp image {path} does not exist")
    try:
        img = np.asarray(read_image(path))
    except Exception as exc:  # imageio raises many types for a bad file
        first = (str(exc).strip().splitlines() or [type(exc).__name__])[0]
        raise EditError(f"cannot read stamp image {path}: {first}") from None
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, 2)
    if img.ndim != 3 or img.shape[2] not in (3, 4) or min(img.shape[:2]) < 1:
        raise EditError(f"stamp image {path} must be greyscale, RGB or RGBA, got shape {img.shape}")
    scale = 65535.0 if img.dtype == np.uint16 else 255.0 if img.dtype.kind in "ui" else 1.0
    img = img.astype(np.float32) / scale
    if img.shape[2] == 3:
        img = np.concatenate([img, np.ones_like(img[..., :1])], 2)
    return np.clip(img, 0, 1)


def solid_shape(name: str, color, resolution: int = 128) -> np.ndarray:
    """[r, r, 4] RGBA of a solid ``name`` (circle, square, ring) in ``color``, anti-aliased edges."""
    if name not in SHAPES:
        raise EditError(f"unknown stamp shape {name!r}; known: {', '.join(SHAPES)}")
    r = resolution
    yy, xx = (np.mgrid[0:r, 0:r] + 0.5) / r * 2 - 1
    rad = np.sqrt(xx**2 + yy**2)
    px = 2.0 / r  # one pixel in these units: the width of the anti-aliased edge
    if name == "circle":
        alpha = np.clip((1 - rad) / px, 0, 1)
    elif name == "square":
        alpha = np.clip((1 - np.maximum(abs(xx), abs(yy))) / px, 0, 1)
    else:
        alpha = np.clip((1 - rad) / px, 0, 1) * np.clip((rad - 0.6) / px, 0, 1)
    rgba = np.empty((r, r, 4), np.float32)
    rgba[..., :3] = np.asarray(color, np.float32)
    rgba[..., 3] = alpha
    return rgba


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Sample [h, w, C] at pixel coordinates (x, y) (pixel centres at +0.5); zero outside."""
    h, w = image.shape[:2]
    pad = np.pad(image, ((1, 1), (1, 1), (0, 0)))  # transparent border: alpha fades to 0 off the image
    fx, fy = x - 0.5 + 1, y - 0.5 + 1
    x0 = np.clip(np.floor(fx).astype(np.int64), 0, w)
    y0 = np.clip(np.floor(fy).astype(np.int64), 0, h)
    ax = np.clip(fx - x0, 0, 1)[:, None]
    ay = np.clip(fy - y0, 0, 1)[:, None]
    out = (pad[y0, x0] * (1 - ax) * (1 - ay) + pad[y0, x0 + 1] * ax * (1 - ay)
           + pad[y0 + 1, x0] * (1 - ax) * ay + pad[y0 + 1, x0 + 1] * ax * ay)
    outside = (fx < 0) | (fx > w + 1) | (fy < 0) | (fy > h + 1)
    out[outside] = 0
    return out


def resolve_placement(view: ScreenView, placement: StampPlacement, faces: torch.Tensor,
                      seen_depths: np.ndarray | None = None) -> tuple[float, float, float]:
    """(centre x, centre y, size in pixels) of ``placement`` in ``view``; ``faces`` the candidate faces
    (their visible centroid is the default centre), ``seen_depths`` depths to fall back on when the centre
    pixel misses the body."""
    h, w = view.ids.ids.shape
    centre = placement.centre
    if centre is None:
        f = np.unique(np.asarray(faces))
        on = f[view.visible[f]]
        centre = view.px[on].mean(0) if len(on) else (w / 2, h / 2)
    cx, cy = float(centre[0]), float(centre[1])
    if placement.unit == "px":
        return cx, cy, placement.size
    zc = float(view.ids.depth[int(np.clip(cy, 0, h - 1)), int(np.clip(cx, 0, w - 1))])
    if not np.isfinite(zc) and seen_depths is not None and len(seen_depths):
        zc = float(np.median(seen_depths))  # the centre misses the body: the depth of what the stamp sees
    if not np.isfinite(zc):
        raise EditError("the stamping view sees none of the selected faces")
    return cx, cy, placement.size * float(view.camera.K[0, 0]) / zc


def stamp_targets(view: ScreenView, means: torch.Tensor, face_of_surfel: torch.Tensor, image: np.ndarray,
                  placement: StampPlacement, surfel_weight: torch.Tensor | None = None, tolerance: float = 0.015
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per-surfel stamp colours and weights.

    view: the stamping view (camera + ID render of the posed mesh); means [N, 3] the candidate surfels'
    world positions in that pose; face_of_surfel [N]; image [h, w, 4] RGBA; surfel_weight [N] optional
    selection weight. tolerance (m): how far behind the visible depth a surfel still counts as visible
    (the fine surfels' offset range plus the mesh's pixel-scale depth error).
    Returns (colors [N, 3], weights [N] in [0, 1], visible [N] bool).
    """
    cam = view.camera
    px, z = cam.project(means.detach().double().numpy())
    h, w = view.ids.ids.shape
    ix = np.floor(np.nan_to_num(px[:, 0], nan=-1.0)).astype(np.int64)
    iy = np.floor(np.nan_to_num(px[:, 1], nan=-1.0)).astype(np.int64)
    inside = (z > 1e-3) & (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    # Facing the camera (a little slack for the silhouette, where grazing faces show their surfels):
    # the depth test alone lets through a surface folded within ``tolerance`` behind the visible one
    # (the inside of the lips, an armpit).
    tri = view.vertices[view.faces].astype(np.float64)
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    to_eye = cam.eye - tri.mean(1)
    cos = (normal * to_eye).sum(1) / np.maximum(np.linalg.norm(normal, axis=1) * np.linalg.norm(to_eye, axis=1), 1e-20)
    facing = (cos > -0.1)[face_of_surfel.numpy()]
    visible = np.zeros(len(z), bool)
    sel = np.nonzero(inside & facing)[0]
    visible[sel] = z[sel] <= view.ids.depth[iy[sel], ix[sel]] + tolerance
    sel = np.nonzero(inside)[0]

    cx, cy, size_px = resolve_placement(view, placement, face_of_surfel, z[visible])
    ih, iw = image.shape[:2]
    scale = max(ih, iw) / size_px  # image pixels per screen pixel
    a = math.radians(placement.rotation)
    dx, dy = px[:, 0] - cx, px[:, 1] - cy
    # Screen y points down: a counter-clockwise rotation on screen is clockwise in these coordinates.
    u = (math.cos(a) * dx - math.sin(a) * dy) * scale + iw / 2
    v = (math.sin(a) * dx + math.cos(a) * dy) * scale + ih / 2
    rgba = np.zeros((len(z), 4), np.float32)
    rgba[sel] = _bilinear(image, u[sel], v[sel])
    weight = rgba[:, 3] * visible
    if surfel_weight is not None:
        weight = weight * surfel_weight.numpy()
    return rgba[:, :3], weight.astype(np.float32), visible
