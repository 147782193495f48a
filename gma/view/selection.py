"""Face selection in screen space (box, lasso/pen), by body part, and its JSON file.

A face is selected when its centre, projected with the view's camera, falls inside the box or the lasso
polygon. By default only faces *facing the camera* are taken (normal towards the eye), which is what a
user painting the visible side of the body expects; faces facing the camera but hidden behind another
part (an arm in front of the torso) are still taken — pass ``front_only=False`` to select through the
body. The computation is a one-off numpy pass over the F faces on a user action, never per frame.

File format (``save_selection``), written atomically::

    {"format": "gma-selection", "version": 1, "body_model": "anny", "num_faces": 27420, "faces": [ids...]}
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.atomic import atomic_write_json
from gma.core.camera import Camera

__all__ = ["SelectionFile", "face_centres_on_screen", "faces_in_box", "faces_in_lasso", "load_selection",
           "points_in_polygon", "save_selection"]

FORMAT = "gma-selection"


def face_centres_on_screen(vertices: np.ndarray, faces: np.ndarray, camera: Camera
                           ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Project face centres. vertices [V, 3] (world), faces [F, 3] -> (pixels [F, 2], depth [F] (camera
    z, m), facing [F] bool: the face normal points towards the camera)."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64)
    a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
    centre = (a + b + c) / 3
    R, t = camera.viewmat[:3, :3].astype(np.float64), camera.viewmat[:3, 3].astype(np.float64)
    pc = centre @ R.T + t
    z = pc[:, 2]
    uvw = pc @ camera.K.astype(np.float64).T
    with np.errstate(divide="ignore", invalid="ignore"):
        px = uvw[:, :2] / uvw[:, 2:3]
    eye = -R.T @ t
    normal = np.cross(b - a, c - a)
    facing = np.einsum("fc,fc->f", normal, eye - centre) > 0
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
    """[F] bool: face centres inside the pixel box ``(x0, y0, x1, y1)`` (corners in any order)."""
    px, z, facing = face_centres_on_screen(vertices, faces, camera)
    x0, x1 = sorted((box[0], box[2]))
    y0, y1 = sorted((box[1], box[3]))
    inside = (px[:, 0] >= x0) & (px[:, 0] <= x1) & (px[:, 1] >= y0) & (px[:, 1] <= y1)
    return inside & _eligible(z, facing, front_only)


def faces_in_lasso(vertices, faces, camera: Camera, polygon, front_only: bool = True) -> np.ndarray:
    """[F] bool: face centres inside the closed pixel polygon [K, 2] (the pen stroke)."""
    px, z, facing = face_centres_on_screen(vertices, faces, camera)
    ok = _eligible(z, facing, front_only)
    out = np.zeros(len(px), bool)
    out[ok] = points_in_polygon(px[ok], polygon)
    return out


@dataclass
class SelectionFile:
    body_model: str
    num_faces: int
    faces: np.ndarray  # [K] int64 sorted face ids


def save_selection(path: str | Path, face_ids, body_model: str, num_faces: int) -> None:
    """Write the selection as JSON, atomically (a crash leaves the old file or the new one)."""
    ids = np.unique(np.asarray(face_ids, np.int64))
    if len(ids) and (ids[0] < 0 or ids[-1] >= num_faces):
        raise ValueError(f"selection holds face ids outside [0, {num_faces})")
    atomic_write_json(path, {"format": FORMAT, "version": 1, "body_model": body_model,
                             "num_faces": int(num_faces), "faces": ids.tolist()})


def load_selection(path: str | Path, body_model: str | None = None, num_faces: int | None = None
                   ) -> SelectionFile:
    """Read a selection file; with ``body_model`` / ``num_faces`` given, refuse one made for another mesh."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"selection file {path} does not exist")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise ValueError(f"{path}: not a selection file (invalid JSON: {exc})") from exc
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a selection file (expected \"format\": \"{FORMAT}\")")
    try:
        sel = SelectionFile(str(data["body_model"]), int(data["num_faces"]), np.asarray(data["faces"], np.int64))
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: malformed selection file ({exc})") from exc
    if sel.faces.ndim != 1 or (len(sel.faces) and (sel.faces.min() < 0 or sel.faces.max() >= sel.num_faces)):
        raise ValueError(f"{path}: face ids must be a list within [0, {sel.num_faces})")
    if body_model is not None and sel.body_model != body_model:
        raise ValueError(f"{path}: selection was made on body model {sel.body_model!r}, not {body_model!r}")
    if num_faces is not None and sel.num_faces != num_faces:
        raise ValueError(f"{path}: selection was made on a mesh of {sel.num_faces} faces, this one has {num_faces}")
    return sel
