"""Screen-space geometry of a selection: projecting face centres, point-in-polygon, and the visibility
test against a face-ID render. One-off numpy passes over the F faces on a user action, never per frame.

(Moved here from ``gma.view.selection``, which re-exports these names.)
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gma.core.camera import Camera
from gma.render.face_id import FaceIdRenderer, IdImage

__all__ = ["ScreenView", "face_centres_on_screen", "faces_in_box", "faces_in_lasso", "points_in_polygon",
           "visible_faces"]

# A face whose centre lies this far behind the visible surface (m) still counts as seen: the ID render
# interpolates depth at pixel centres, not at the face centre, and surfels sit off the mesh by up to a cm.
VISIBLE_TOLERANCE = 0.01


def face_centres_on_screen(vertices: np.ndarray, faces: np.ndarray, camera: Camera
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project face centres. vertices [V, 3] (world), faces [F, 3] -> (pixels [F, 2], depth [F] (camera
    z, m), facing [F] bool: the face normal points towards the camera)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    centre = (a + b + c) / 3
    px, z = camera.project(centre)
    normal = np.cross(b - a, c - a)
    facing = np.einsum("fc,fc->f", normal, camera.eye - centre) > 0
    return px, z, facing


def points_in_polygon(points: np.ndarray, polygon: np.ndarray) -> np.ndarray:
    """Even-odd rule: [P, 2] points inside the closed polygon [K, 2] (any winding, self-crossing allowed)."""
    pts = np.asarray(points, np.float64)
    poly = np.asarray(polygon, np.float64)
    inside = np.zeros(len(pts), bool)
    if len(poly) < 3:
        return inside
    x, y = pts[:, 0], pts[:, 1]
    x0, y0 = poly[:, 0], poly[:, 1]
    x1, y1 = np.roll(x0, -1), np.roll(y0, -1)
    for i in range(len(poly)):  # loop over polygon edges (tens to hundreds), vectorised over points
        crosses = (y0[i] > y) != (y1[i] > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            xi = x0[i] + (y - y0[i]) * (x1[i] - x0[i]) / (y1[i] - y0[i])
        inside ^= crosses & (x < xi)
    return inside


def _eligible(z: np.ndarray, facing: np.ndarray, front_only: bool) -> np.ndarray:
    ok = z > 1e-3  # in front of the camera
    return ok & facing if front_only else ok


def faces_in_box(vertices, faces, camera: Camera, box, front_only: bool = True) -> np.ndarray:
    """[F] bool: face centres inside the pixel box ``(x0, y0, x1, y1)`` (corners in any order). No
    occlusion test: see :class:`ScreenView` for selections of visible faces only."""
    px, z, facing = face_centres_on_screen(vertices, faces, camera)
    x0, x1 = sorted((box[0], box[2]))
    y0, y1 = sorted((box[1], box[3]))
    inside = (px[:, 0] >= x0) & (px[:, 0] <= x1) & (px[:, 1] >= y0) & (px[:, 1] <= y1)
    return inside & _eligible(z, facing, front_only)


def faces_in_lasso(vertices, faces, camera: Camera, polygon, front_only: bool = True) -> np.ndarray:
    """[F] bool: face centres inside the closed pixel polygon [K, 2] (the pen stroke). No occlusion test."""
    px, z, facing = face_centres_on_screen(vertices, faces, camera)
    ok = _eligible(z, facing, front_only)
    out = np.zeros(len(px), bool)
    out[ok] = points_in_polygon(px[ok], polygon)
    return out


def visible_faces(px: np.ndarray, z: np.ndarray, facing: np.ndarray, ids: IdImage,
                  tolerance: float = VISIBLE_TOLERANCE) -> np.ndarray:
    """[F] bool: faces seen in the ID render — facing the camera, centre inside the image, and either
    the face itself is drawn at its centre pixel or its centre is within ``tolerance`` (m) of the visible
    depth there (a face smaller than a pixel may lose its pixel to a neighbour yet be in plain view)."""
    h, w = ids.ids.shape
    ok = facing & (z > 1e-3) & np.isfinite(px).all(1)
    ix = np.clip(np.floor(np.nan_to_num(px[:, 0], nan=-1)), -1, w).astype(np.int64)
    iy = np.clip(np.floor(np.nan_to_num(px[:, 1], nan=-1)), -1, h).astype(np.int64)
    ok &= (ix >= 0) & (ix < w) & (iy >= 0) & (iy < h)
    out = np.zeros(len(z), bool)
    sel = np.nonzero(ok)[0]
    shown = ids.ids[iy[sel], ix[sel]]
    depth = ids.depth[iy[sel], ix[sel]]
    out[sel] = (shown == sel) | ((shown >= 0) & (z[sel] <= depth + tolerance))
    return out


@dataclass
class ScreenView:
    """One camera's view of the posed morphed mesh, with the face-ID render that decides visibility.

    ``vertices`` [V, 3] world (m), ``faces`` [F, 3], ``ids`` the ID render; ``px`` [F, 2] face-centre
    pixels, ``z`` [F] camera depth, ``visible`` [F] bool (see :func:`visible_faces`)."""

    camera: Camera
    vertices: np.ndarray
    faces: np.ndarray
    ids: IdImage
    px: np.ndarray
    z: np.ndarray
    visible: np.ndarray
    name: str | None = None  # a named view's name (front, back, ...), recorded in stamp history

    @staticmethod
    def render(renderer: FaceIdRenderer, vertices, faces, camera: Camera, name: str | None = None) -> ScreenView:
        v = np.asarray(vertices, np.float32)
        f = np.asarray(faces, np.int64)
        ids = renderer.render(v, camera)
        px, z, facing = face_centres_on_screen(v, f, camera)
        return ScreenView(camera, v, f, ids, px, z, visible_faces(px, z, facing, ids), name)

    @property
    def num_faces(self) -> int:
        return len(self.faces)

    def face_at(self, x: float, y: float) -> int:
        """The face drawn at pixel (x, y), or -1 (background / outside the image)."""
        h, w = self.ids.ids.shape
        ix, iy = int(np.floor(x)), int(np.floor(y))
        return int(self.ids.ids[iy, ix]) if 0 <= ix < w and 0 <= iy < h else -1
