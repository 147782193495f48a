"""What the training frames saw of an avatar, and the features of what they did not.

:func:`observe_faces` counts, per face, the visible pixels of face-ID renders of the posed mesh at every
training camera, each weighted by the cosine between the face's normal and the direction to the camera
(a face seen at a grazing angle says little about its colour). :func:`seen_score` maps that to [0, 1],
saved in the ``.gma`` as ``face_seen``; a face under 0.5 (:data:`SEEN`) is "unseen" (``gma edit --select
unseen``, the viewer's and ``gma eval``'s seen / guessed overlay).

:func:`fill_unseen_faces` is the step after a fit: the decoded colours of the unseen faces are filled
from the seen ones (:func:`gma.avatar.fill.fill_unseen`: over the surface within body-part groups, plus
a front-to-back prior for the garments), then turned into ordinary features by the same solve as paint
(:func:`gma.edit.paint.paint_features`), so paint, stamp and transfer work on them like on any face.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
import torch

from gma.avatar.fill import fill_groups, fill_unseen
from gma.body.geometry import face_adjacency, face_centers, mirror_faces
from gma.core.camera import Camera
from gma.edit.errors import EditError
from gma.edit.paint import paint_features

__all__ = ["SEEN", "SEEN_PIXELS", "depth_axis", "face_areas", "fill_unseen_faces", "guessed_share",
           "observe_faces", "seen_score", "unseen_mask"]

# A face's weighted pixel count at which its seen score is 1 - 1/e: about one head-on pixel summed over
# the clip. Below SEEN (0.7 px) the fit had next to nothing to learn its colour from.
SEEN_PIXELS = 1.0
SEEN = 0.5


def observe_faces(renderer, faces: torch.Tensor, meshes: Iterable[tuple[np.ndarray, Camera]],
                  supersample: int = 2) -> np.ndarray:
    """[F] float64: per face of ``faces`` [F, 3] (the mesh ``renderer``, a
    :class:`gma.edit.idrender.FaceIdRenderer`, draws), the sum over ``meshes`` (pairs of posed vertices
    [V, 3] and the camera that saw them) of its visible pixels times the cosine of its viewing angle (0
    when turned away). Pixels are counted at the camera's resolution; ``supersample`` renders at that
    factor (then divides), so a face smaller than a pixel still counts for its share."""
    from gma.avatar.posing import face_away_cosine

    faces = torch.as_tensor(faces).long()
    num_faces = len(faces)
    total = np.zeros(num_faces)
    for verts, cam in meshes:
        s = int(supersample)
        K = np.asarray(cam.K, np.float64).copy()
        K[:2] *= s
        big = Camera(cam.viewmat, K, int(cam.width) * s, int(cam.height) * s)
        ids = renderer.render(verts, big).ids
        pixels = np.bincount(ids[ids >= 0].ravel(), minlength=num_faces)[:num_faces] / (s * s)
        cosine = -face_away_cosine(torch.as_tensor(np.asarray(verts), dtype=torch.float32), faces,
                                   torch.as_tensor(np.asarray(cam.viewmat), dtype=torch.float32))
        total += pixels * cosine.clamp_min(0.0).double().numpy()
    return total


def seen_score(pixels) -> torch.Tensor:
    """[F] float32 in [0, 1]: 1 - exp(-pixels / SEEN_PIXELS) of :func:`observe_faces`' counts."""
    p = torch.as_tensor(np.asarray(pixels, np.float64))
    return (1.0 - torch.exp(-p.clamp_min(0) / SEEN_PIXELS)).float()


def unseen_mask(avatar) -> torch.Tensor:
    """[F] bool: the faces of ``avatar`` no training frame showed well (``face_seen`` < :data:`SEEN`).
    EditError for an avatar without the record (fitted before GMA saved it, or not by ``gma fit``)."""
    if avatar.face_seen is None:
        raise EditError("this avatar has no record of what its training frames saw (fitted by an older GMA): "
                        "fit it again to select 'unseen'")
    return avatar.face_seen < SEEN


def face_areas(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[F] triangle areas of a mesh (m²)."""
    tri = vertices[faces.long()]
    return 0.5 * torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]).norm(dim=-1)


def guessed_share(avatar, body) -> dict:
    """How much of ``avatar`` was filled in rather than seen: shares of faces and of body surface area."""
    unseen = unseen_mask(avatar)
    area = face_areas(avatar.rest_vertices, body.faces)
    return {"faces": round(float(unseen.float().mean()), 4),
            "area": round(float(area[unseen].sum() / area.sum().clamp_min(1e-12)), 4)}


def depth_axis(rest_vertices: torch.Tensor) -> int:
    """The body's front-back axis in its rest frame: not x (left-right, the mirror plane's normal) and not
    the longest extent (up)."""
    extent = (rest_vertices.max(0).values - rest_vertices.min(0).values).tolist()
    up = 1 if extent[1] > extent[2] else 2
    return 3 - up  # of the axes 1 and 2, the one that is not up


@torch.no_grad()
def fill_unseen_faces(avatar, body, seen: torch.Tensor, mirror: bool = True, front_back: float = 0.5) -> dict:
    """Store ``seen`` [F] (:func:`seen_score`) in ``avatar.face_seen`` and give the faces it marks unseen
    new ``f_tex``, solved so they decode to colours filled from the seen faces. ``mirror``: a face whose
    left-right mirror was seen counts as known and keeps its features (the fit's symmetry prior taught
    them from its mirror). ``front_back``: weight of the front-to-back prior (:mod:`gma.avatar.fill`).
    Returns a summary, also written to ``avatar.info["unseen"]``."""
    model = avatar.model
    if model.direct:
        raise EditError("a 'direct' avatar has no features to fill")
    seen = torch.as_tensor(seen, dtype=torch.float32)
    if tuple(seen.shape) != (model.num_faces,) or not bool(torch.isfinite(seen).all()):
        raise ValueError(f"seen must be [{model.num_faces}] finite values, got {list(seen.shape)}")
    avatar.face_seen = seen.clamp(0, 1)
    known = (seen >= SEEN).numpy()
    if mirror:
        try:
            known = known | known[mirror_faces(avatar.rest_vertices, body.faces).numpy()]
        except ValueError:
            pass  # a body mesh without left-right symmetry: no mirror knowledge, the fill does it all
    nk = model.config.fine_per_face
    _, colors, _ = model.fine_outputs()
    result = fill_unseen(colors.reshape(model.num_faces, nk * 3).double().numpy(), known,
                         face_adjacency(body.faces.long()).numpy(), fill_groups(body.regions),
                         face_centers(avatar.rest_vertices.double(), body.faces).numpy(),
                         depth_axis(avatar.rest_vertices), front_back)
    ids = torch.as_tensor(np.nonzero(result.how > 0)[0], dtype=torch.long)
    if len(ids):
        target = torch.as_tensor(result.values[ids.numpy()], dtype=torch.float32).reshape(-1, nk, 3)
        feats, _ = paint_features(model, ids, target.clamp(0, 1))
        model.f_tex[ids] = feats
    summary = {"guessed": guessed_share(avatar, body), "filled": result.summary(), "front_back": front_back,
               "mirror": bool(mirror)}
    avatar.info["unseen"] = summary
    return summary
