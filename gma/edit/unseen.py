"""What the training frames saw of an avatar, and the features of what they did not.

:func:`observe_faces` measures, per face, how much of it face-ID renders of the posed mesh show at every
training camera (visible pixels over its projected area), each frame weighted by the cosine between the
face's normal and the direction to the camera (a face seen at a grazing angle says little about its
colour). :func:`seen_score` maps that to [0, 1], saved in the ``.gma`` as ``face_seen``; a face under 0.5
(:data:`SEEN`) is "unseen" (``gma edit --select unseen``, ``gma eval``'s seen / guessed picture).

:func:`fill_unseen_faces` is the step after a fit: the decoded colours of the faces not seen well are
filled from the faces seen well (:func:`gma.avatar.fill.fill_unseen`: from the mirror face, over the
surface within body-part groups, a front-to-back prior per group, the crown for the back of the head),
then turned into ordinary features by the same solve as paint (:func:`gma.edit.paint.paint_features`), so
paint, stamp and transfer work on them like on any face. :func:`untrained_faces` and
:func:`default_colour_faces` count what a fit left at its starting features (``benchmarks/unseen_real.py``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable

import numpy as np
import torch

from gma.avatar.fill import FRONT_BACK, Orientation, fill_groups, fill_unseen
from gma.body.geometry import face_adjacency, face_centers, mirror_faces
from gma.core.camera import Camera
from gma.edit.errors import EditError
from gma.edit.paint import paint_features

__all__ = ["ID_RESOLUTION", "SEEN", "SEEN_COVER", "SOURCE", "AfterFit", "body_orientation", "default_colour_faces",
           "depth_axis", "face_areas", "fill_unseen_faces", "guessed_share", "initial_features", "observe_faces",
           "projected_areas", "seen_picture", "seen_score", "unseen_mask", "untrained_faces"]

# A face's summed cover (:func:`observe_faces`) at which its seen score is 1 - 1/e: half of it seen in one
# frame head-on. Below SEEN (a cover of 0.35) the fit had little to learn the face's colour from.
SEEN_COVER = 0.5
SEEN = 0.5
# Faces the fill keeps and takes values from: seen well (a summed cover of 0.8). The others are filled, those
# seen only at a grazing angle included: the fit blends such faces with the background at the silhouette.
SOURCE = 0.8
# Face-ID renders are made at least this large (longest side, pixels), whatever the fit's resolution, so
# that faces smaller than a fitting pixel are still found where they show.
ID_RESOLUTION = 512


def observe_faces(renderer, faces: torch.Tensor, meshes: Iterable[tuple[np.ndarray, Camera]]) -> np.ndarray:
    """[F] float64: per face of ``faces`` [F, 3] (the mesh ``renderer``, a
    :class:`gma.render.face_id.FaceIdRenderer`, draws), its cover summed over ``meshes`` (pairs of posed
    vertices [V, 3] and the camera that saw them): the visible fraction of its projected area (pixels of
    a face-ID render over its triangle's area in pixels; occluded parts do not count) times the cosine of
    its viewing angle (0 when turned away). A fraction, not a pixel count, so the score does not depend on
    the fitting resolution."""
    from gma.avatar.posing import face_away_cosine

    faces = torch.as_tensor(faces).long()
    total = np.zeros(len(faces))
    for verts, cam in meshes:
        s = max(1, math.ceil(ID_RESOLUTION / max(int(cam.width), int(cam.height))))
        K = np.asarray(cam.K, np.float64).copy()
        K[:2] *= s
        big = Camera(np.asarray(cam.viewmat, np.float32), K.astype(np.float32), int(cam.width) * s,
                     int(cam.height) * s)
        ids = renderer.render(verts, big).ids
        pixels = np.bincount(ids[ids >= 0].ravel(), minlength=len(faces))[:len(faces)]
        area = projected_areas(np.asarray(verts, np.float64), faces.numpy(), big)
        cover = np.minimum(pixels / np.maximum(area, 1e-9), 1.0)
        v = torch.as_tensor(np.asarray(verts), dtype=torch.float32)
        cosine = -face_away_cosine(v, faces, torch.as_tensor(big.viewmat, dtype=torch.float32))
        total += cover * cosine.clamp_min(0.0).double().numpy()
    return total


def projected_areas(vertices: np.ndarray, faces: np.ndarray, camera: Camera) -> np.ndarray:
    """[F] area in pixels of each triangle projected by ``camera`` (0 for one behind the camera)."""
    view = np.asarray(camera.viewmat, np.float64)
    pc = vertices @ view[:3, :3].T + view[:3, 3]
    z = np.maximum(pc[:, 2], 1e-6)
    px = (pc[:, :2] / z[:, None]) @ np.asarray(camera.K, np.float64)[:2, :2].T
    a, b, c = px[faces[:, 0]], px[faces[:, 1]], px[faces[:, 2]]
    area = 0.5 * np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))
    return np.where((pc[faces, 2] > 1e-3).all(1), area, 0.0)


def seen_score(cover) -> torch.Tensor:
    """[F] float32 in [0, 1]: 1 - exp(-cover / SEEN_COVER) of :func:`observe_faces`' summed cover."""
    c = torch.as_tensor(np.asarray(cover, np.float64))
    return (1.0 - torch.exp(-c.clamp_min(0) / SEEN_COVER)).float()


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


def initial_features(avatar, seed: int) -> torch.Tensor:
    """[F, k] the texture features ``avatar`` had before its fit (``gma fit --seed``; the trainer starts
    subject i of a multi-person fit at seed + i)."""
    from gma.avatar.model import AvatarModel

    model = avatar.model
    return AvatarModel(model.config, model.faces, avatar.rest_vertices, seed=seed).f_tex.detach()


def untrained_faces(model, start: torch.Tensor) -> np.ndarray:
    """[F] bool: the faces of ``model`` whose texture features are still exactly ``start`` [F, k]
    (:func:`initial_features`): no step of the fit and no fill changed them, so they decode to the
    untrained default colour."""
    return (model.f_tex.detach() == start).all(1).numpy()


@torch.no_grad()
def default_colour_faces(model, start: torch.Tensor, tolerance: float = 0.02) -> np.ndarray:
    """[F] bool: the faces of ``model`` whose decoded colours lie within ``tolerance`` (0-1, every surfel
    and channel) of what its decoders make of the features ``start`` [F, k] (:func:`initial_features`):
    faces the fit left at the untrained default colour (the grey of a never-seen back)."""
    nk = model.config.fine_per_face
    _, now, _ = model.fine_outputs()
    default = torch.sigmoid(model.T_color(torch.cat([start, model.pe], -1))).reshape(-1, nk, 3)
    return ((now - default).abs().amax((1, 2)) <= tolerance).numpy()


def depth_axis(rest_vertices: torch.Tensor) -> int:
    """The body's front-back axis in its rest frame: not x (left-right, the mirror plane's normal) and not
    the longest extent (up)."""
    extent = (rest_vertices.max(0).values - rest_vertices.min(0).values).tolist()
    up = 1 if extent[1] > extent[2] else 2
    return 3 - up  # of the axes 1 and 2, the one that is not up


def body_orientation(rest_vertices: torch.Tensor, faces: torch.Tensor, up_axis: str) -> Orientation:
    """The rest-pose face normals and the body's up and forward axes (forward = left x up with left +x:
    Anny's -y, SMPL-X's +z) for the crown prior of :func:`gma.avatar.fill.fill_unseen`."""
    v = rest_vertices.double()
    f = faces.long()
    normals = torch.linalg.cross(v[f[:, 1]] - v[f[:, 0]], v[f[:, 2]] - v[f[:, 0]])
    up = np.eye(3)[{"x": 0, "y": 1, "z": 2}[up_axis]]
    return Orientation(torch.nn.functional.normalize(normals, dim=-1).numpy(), up, np.cross(np.eye(3)[0], up))


@torch.no_grad()
def fill_unseen_faces(avatar, body, seen: torch.Tensor, mirror: bool = True, front_back=None,
                      source: float = SOURCE, crown: bool = True) -> dict:
    """Store ``seen`` [F] (:func:`seen_score`) in ``avatar.face_seen`` and give the faces not seen well (a
    score under ``source``: the unseen ones, and those seen only at a grazing angle, whose colour the fit
    blended with the background at the silhouette) new ``f_tex``, solved so they decode to colours filled
    from the faces seen well. ``mirror``: such a face whose left-right mirror was seen well takes its
    mirror's colour. ``front_back``: weights of the front-to-back prior (:mod:`gma.avatar.fill`; default
    its ``FRONT_BACK``); ``crown``: the crown prior of the head (off: an ablation). Returns a summary, also
    written to ``avatar.info["unseen"]``."""
    model = avatar.model
    if model.direct:
        raise EditError("a 'direct' avatar has no features to fill")
    seen = torch.as_tensor(seen, dtype=torch.float32)
    if tuple(seen.shape) != (model.num_faces,) or not bool(torch.isfinite(seen).all()):
        raise ValueError(f"seen must be [{model.num_faces}] finite values, got {list(seen.shape)}")
    avatar.face_seen = seen.clamp(0, 1)
    mirror_of = None
    if mirror:
        try:
            mirror_of = mirror_faces(avatar.rest_vertices, body.faces).numpy()
        except ValueError:
            pass  # a body mesh without left-right symmetry: no mirror knowledge, the fill does it all
    orientation = body_orientation(avatar.rest_vertices, body.faces, body.up_axis) if crown else None
    nk = model.config.fine_per_face
    _, colors, _ = model.fine_outputs()
    result = fill_unseen(colors.reshape(model.num_faces, nk * 3).double().numpy(), (seen >= source).numpy(),
                         face_adjacency(body.faces.long()).numpy(), fill_groups(body.regions),
                         face_centers(avatar.rest_vertices.double(), body.faces).numpy(),
                         depth_axis(avatar.rest_vertices), front_back, mirror_of=mirror_of,
                         orientation=orientation)
    ids = torch.as_tensor(np.nonzero(result.how > 0)[0], dtype=torch.long)
    if len(ids):
        target = torch.as_tensor(result.values[ids.numpy()], dtype=torch.float32).reshape(-1, nk, 3)
        feats, _ = paint_features(model, ids, target.clamp(0, 1))
        model.f_tex[ids] = feats
    summary = {"guessed": guessed_share(avatar, body), "filled": result.summary(),
               "front_back": front_back if front_back is not None else dict(FRONT_BACK), "mirror": bool(mirror),
               "crown": bool(crown)}
    avatar.info["unseen"] = summary
    return summary


class AfterFit:
    """The step after a fit (``Trainer(finish=AfterFit(ctx))``): counts what the training frames saw of
    each face with face-ID renders, stores it in the avatar and, with ``fill``, fills the unseen faces
    (:func:`fill_unseen_faces`). ``ctx``: the GPU context (default: the shared one, made on first use)."""

    def __init__(self, ctx=None, fill: bool = True, front_back=None, source: float = SOURCE, crown: bool = True):
        self.ctx, self.fill, self.front_back, self.source, self.crown = ctx, fill, front_back, source, crown
        self._renderer = None

    def _renderer_for(self, body):
        if self._renderer is None or self._renderer.num_faces != body.num_faces:
            from gma.gpu import get_context
            from gma.render.face_id import FaceIdRenderer

            self.ctx = self.ctx or get_context()
            self._renderer = FaceIdRenderer(self.ctx, body.faces.numpy())
        return self._renderer

    def __call__(self, avatar, body, meshes, mirror: bool = True) -> dict:
        seen = seen_score(observe_faces(self._renderer_for(body), body.faces, meshes))
        if self.fill:
            return fill_unseen_faces(avatar, body, seen, mirror, self.front_back, self.source, self.crown)
        avatar.face_seen = seen
        avatar.info["unseen"] = summary = {"guessed": guessed_share(avatar, body), "filled": None}
        return summary


# Colours of the seen / guessed picture: a face's colour runs from GUESSED (score 0) to SEEN_COLOR (1).
GUESSED_COLOR = np.array([0.85, 0.2, 0.6])
SEEN_COLOR = np.array([0.3, 0.72, 0.35])


@torch.no_grad()
def seen_picture(avatar, body, ctx=None, size: int = 256) -> np.ndarray:
    """[size, 4·size, 3] float in [0, 1]: the avatar's mesh in its canonical pose from the front, back,
    left and right, each face coloured by its seen score (green seen, magenta guessed), lit by its
    facing, on white. EditError for an avatar without the record."""
    from gma.avatar.posing import face_away_cosine
    from gma.edit.views import NAMED_VIEWS, canonical_vertices, named_view
    from gma.gpu import get_context
    from gma.render.face_id import FaceIdRenderer

    unseen_mask(avatar)  # the error for an avatar without the record
    verts = canonical_vertices(body, avatar.model.vertex_offsets(), avatar.shape)
    score = avatar.face_seen.numpy()[:, None]
    colors = (1 - score) * GUESSED_COLOR + score * SEEN_COLOR
    renderer = FaceIdRenderer(ctx or get_context(), body.faces.numpy())
    panels = []
    for name in NAMED_VIEWS:
        cam = named_view(name, verts.numpy(), body.up_axis, size, size)
        ids = renderer.render(verts.numpy(), cam).ids
        light = (-face_away_cosine(verts, body.faces, torch.as_tensor(cam.viewmat))).abs().numpy()
        shaded = colors * (0.35 + 0.65 * light[:, None])
        panels.append(np.where(ids[..., None] >= 0, shaded[np.clip(ids, 0, None)], 1.0))
    return np.concatenate(panels, 1).astype(np.float32)
