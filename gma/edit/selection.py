"""``Selection``: faces of the avatar's body, each with a weight in (0, 1] (1 for a hard selection, less
at a brush's soft edge), and its JSON file (the viewer's format).

Built from screen space for one camera and pose (box, lasso, circular brush: only faces visible in a
face-ID render, see :class:`gma.edit.screen.ScreenView`), from body part / region names, from a file,
or by a magic wand (flood fill over face adjacency while a per-face value stays within a tolerance of
the seed face's); combined by union / subtract / intersect / invert and grown or shrunk by rings of
neighbouring faces, or mirrored across the body's left-right plane (``mirror_map``).

File format (``save``), written atomically::

    {"format": "gma-selection", "version": 1, "body_model": "anny", "num_faces": 27420, "faces": [ids...],
     "weights": [w...]}        # "weights" only for a soft selection
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gma.edit.errors import EditError
from gma.edit.limits import MAX_RINGS, MAX_SCREEN_PIXELS, check_number, check_pixel
from gma.edit.screen import ScreenView, points_in_polygon

__all__ = ["FaceGraph", "Selection", "SelectionFile", "load_selection", "mirror_map", "save_selection"]

FORMAT = "gma-selection"


def _check_rings(what: str, rings) -> int:
    """A ring count for grow / shrink: a whole number in [0, MAX_RINGS]."""
    n = check_number(f"{what} rings", rings, 0, MAX_RINGS)
    if n != int(n):
        raise EditError(f"{what} rings: must be a whole number, got {n:g}")
    return int(n)


class FaceGraph:
    """Edge adjacency of a mesh's faces as a scipy CSR matrix [F, F] (built once per body)."""

    def __init__(self, faces: torch.Tensor):
        import scipy.sparse as sp

        from gma.body.geometry import face_adjacency

        f = int(faces.shape[0])
        pairs = face_adjacency(torch.as_tensor(faces).long()).numpy()
        i = np.concatenate([pairs[:, 0], pairs[:, 1]])
        j = np.concatenate([pairs[:, 1], pairs[:, 0]])
        self.num_faces = f
        self.matrix = sp.csr_matrix((np.ones(len(i), np.float32), (i, j)), shape=(f, f))

    def ring(self, mask: np.ndarray) -> np.ndarray:
        """[F] bool: ``mask`` plus every face sharing an edge with it."""
        return mask | (self.matrix @ mask.astype(np.float32) > 0)


def mirror_map(body, shape: torch.Tensor | None = None) -> torch.Tensor:
    """[F] each face's mirror face across the body's left-right plane, from the rest mesh of ``shape``
    (default: the body's default) without any mesh-layer offsets, which need not be symmetric. EditError
    when the body mesh is not left-right symmetric."""
    from gma.body.geometry import mirror_faces

    rest = body.rest_vertices(body.check_params(body.canonical_params(shape)))
    try:
        return mirror_faces(rest, body.faces)
    except ValueError as exc:
        raise EditError(str(exc)) from None


@dataclass(frozen=True, eq=False)
class Selection:
    """``faces`` [M] int64 sorted unique ids < ``num_faces``; ``weights`` [M] float32 in (0, 1], or None
    for a hard selection (all 1)."""

    faces: torch.Tensor
    num_faces: int
    weights: torch.Tensor | None = None

    # -- construction ---------------------------------------------------------------------------------
    @staticmethod
    def from_mask(mask, weights=None) -> Selection:
        """From a [F] bool mask, optionally with [F] per-face weights (faces of weight <= 0 are dropped)."""
        mask = torch.as_tensor(np.asarray(mask), dtype=torch.bool)
        n = int(mask.shape[0])
        if weights is None:
            return Selection(torch.nonzero(mask).reshape(-1), n)
        w = torch.as_tensor(np.asarray(weights), dtype=torch.float32).clamp(0, 1)
        keep = mask & (w > 0)
        ids = torch.nonzero(keep).reshape(-1)
        ws = w[ids]
        return Selection(ids, n, None if bool((ws == 1).all()) else ws)

    @staticmethod
    def from_ids(ids, num_faces: int, weights=None) -> Selection:
        ids = torch.as_tensor(np.asarray(ids), dtype=torch.long).reshape(-1)
        if len(ids) and (int(ids.min()) < 0 or int(ids.max()) >= num_faces):
            raise EditError(f"selection holds face ids outside [0, {num_faces})")
        mask = torch.zeros(num_faces, dtype=torch.bool)
        mask[ids] = True
        if weights is None:
            return Selection.from_mask(mask)
        w = torch.zeros(num_faces)
        w[ids] = torch.as_tensor(np.asarray(weights), dtype=torch.float32).reshape(-1)
        return Selection.from_mask(mask, w)

    @staticmethod
    def everything(num_faces: int) -> Selection:
        return Selection(torch.arange(num_faces), num_faces)

    @staticmethod
    def from_regions(body, *names: str) -> Selection:
        """Union of body regions / part labels (``body.region_mask``: head, torso, arms, hands, legs, feet,
        upper_body, lower_body, or a fine label such as hand.L)."""
        mask = torch.zeros(body.num_faces, dtype=torch.bool)
        for name in names:
            try:
                mask |= body.region_mask(name)
            except ValueError as exc:
                raise EditError(str(exc)) from None
        return Selection.from_mask(mask)

    @staticmethod
    def unseen(avatar) -> Selection:
        """The faces no training frame of ``avatar`` showed well (their look was filled in, not seen:
        :func:`gma.edit.unseen.unseen_mask`); EditError for an avatar without that record."""
        from gma.edit.unseen import unseen_mask

        return Selection.from_mask(unseen_mask(avatar))

    @staticmethod
    def load(path, body_model: str | None = None, num_faces: int | None = None) -> Selection:
        """A selection file (see module doc); refuses one made for another body model or mesh."""
        sf = load_selection(path, body_model, num_faces)
        return Selection.from_ids(sf.faces, sf.num_faces, sf.weights)

    @staticmethod
    def box(view: ScreenView, box) -> Selection:
        """Visible faces whose centre is inside the pixel box ``(x0, y0, x1, y1)`` (any corner order)."""
        box = check_pixel("box", box)
        if len(box) != 4:
            raise EditError(f"box: expected 4 numbers (x0, y0, x1, y1), got {len(box)}")
        x0, x1 = sorted((box[0], box[2]))
        y0, y1 = sorted((box[1], box[3]))
        px = view.px
        inside = (px[:, 0] >= x0) & (px[:, 0] <= x1) & (px[:, 1] >= y0) & (px[:, 1] <= y1)
        return Selection.from_mask(inside & view.visible)

    @staticmethod
    def lasso(view: ScreenView, polygon) -> Selection:
        """Visible faces whose centre is inside the closed pixel polygon [K, 2] (a pen stroke)."""
        out = np.zeros(view.num_faces, bool)
        vis = np.nonzero(view.visible)[0]
        out[vis] = points_in_polygon(view.px[vis], polygon)
        return Selection.from_mask(out)

    @staticmethod
    def brush(view: ScreenView, centre, radius: float, falloff: float = 0.5) -> Selection:
        """Visible faces within ``radius`` pixels of ``centre`` (x, y); weight 1 inside the inner
        ``(1 - falloff)·radius``, then a smoothstep down to 0 at ``radius`` (soft edge)."""
        radius = check_number("brush radius", radius, 0.0, MAX_SCREEN_PIXELS, "px", low_open=True)
        falloff = check_number("brush falloff", falloff, 0.0, 1.0)
        d = np.linalg.norm(view.px - np.asarray(check_pixel("brush centre", centre), np.float64), axis=1)
        inner = radius * (1.0 - falloff)
        t = np.clip((radius - d) / max(radius - inner, 1e-9), 0, 1)
        w = np.where(np.isfinite(d), t * t * (3 - 2 * t), 0.0)  # smoothstep
        return Selection.from_mask(view.visible & (w > 0), w)

    @staticmethod
    def wand(graph: FaceGraph, values, seed: int, tolerance: float) -> Selection:
        """Magic wand: the faces connected to ``seed`` through edge-adjacent faces whose ``values`` [F, C]
        (mean decoded colour, or f_tex) are within ``tolerance`` (Euclidean) of the seed face's value.
        Compared with the seed, not neighbour to neighbour, so a slow gradient does not leak everywhere."""
        from scipy.sparse.csgraph import connected_components

        tolerance = check_number("wand tolerance", tolerance, 0.0, math.inf)
        vals = np.asarray(values, np.float64)
        if not 0 <= seed < len(vals):
            raise EditError(f"wand seed face {seed} is not on the body (0..{len(vals) - 1})")
        near = np.linalg.norm(vals - vals[seed], axis=1) <= tolerance
        sub = graph.matrix[near][:, near]
        _, labels = connected_components(sub, directed=False)
        idx = np.nonzero(near)[0]
        comp = labels[np.searchsorted(idx, seed)]
        mask = np.zeros(len(vals), bool)
        mask[idx[labels == comp]] = True
        return Selection.from_mask(mask)

    # -- queries --------------------------------------------------------------------------------------
    def __len__(self) -> int:
        return int(self.faces.numel())

    @property
    def soft(self) -> bool:
        return self.weights is not None

    def mask(self) -> torch.Tensor:
        """[F] bool."""
        m = torch.zeros(self.num_faces, dtype=torch.bool)
        m[self.faces] = True
        return m

    def face_weights(self) -> torch.Tensor:
        """[M] weight of each selected face (ones for a hard selection)."""
        return torch.ones(len(self)) if self.weights is None else self.weights

    def dense_weights(self) -> torch.Tensor:
        """[F] weight per face, 0 outside."""
        w = torch.zeros(self.num_faces)
        w[self.faces] = self.face_weights()
        return w

    def require(self, what: str = "selection") -> Selection:
        """Self, or an EditError when empty (an edit of nothing is a mistake to report, not a no-op)."""
        if len(self) == 0:
            raise EditError(f"the {what} is empty: no faces selected")
        return self

    # -- set algebra (weights: max for union, w·(1 - w_other) for subtract, min for intersect) ---------
    def _check(self, other: Selection) -> None:
        if other.num_faces != self.num_faces:
            raise EditError(f"selections of meshes with {self.num_faces} and {other.num_faces} faces")

    def union(self, other: Selection) -> Selection:
        self._check(other)
        w = torch.maximum(self.dense_weights(), other.dense_weights())
        return Selection.from_mask(self.mask() | other.mask(), w)

    def subtract(self, other: Selection) -> Selection:
        self._check(other)
        return Selection.from_mask(self.mask(), self.dense_weights() * (1 - other.dense_weights()))

    def intersect(self, other: Selection) -> Selection:
        self._check(other)
        w = torch.minimum(self.dense_weights(), other.dense_weights())
        return Selection.from_mask(self.mask() & other.mask(), w)

    def invert(self) -> Selection:
        """Every face not fully selected, weighted 1 - w."""
        return Selection.from_mask(torch.ones(self.num_faces, dtype=torch.bool), 1 - self.dense_weights())

    def grow(self, graph: FaceGraph, rings: int = 1) -> Selection:
        """Add ``rings`` rings of edge-adjacent faces (weight of a new face: 1)."""
        m = self.mask().numpy()
        for _ in range(_check_rings("grow", rings)):
            m = graph.ring(m)
        w = self.dense_weights().numpy().copy()
        w[m & (w == 0)] = 1.0
        return Selection.from_mask(m, w)

    def shrink(self, graph: FaceGraph, rings: int = 1) -> Selection:
        """Drop the faces within ``rings`` rings of an unselected face."""
        out = ~self.mask().numpy()
        for _ in range(_check_rings("shrink", rings)):
            out = graph.ring(out)
        return Selection.from_mask(~out, self.dense_weights())

    def mirrored(self, mirror: torch.Tensor) -> Selection:
        """The mirror image across the body's left-right plane: face ``mirror[f]`` for each selected face
        ``f``, same weight (``mirror`` [F]: :func:`gma.body.geometry.mirror_faces`)."""
        if len(mirror) != self.num_faces:
            raise EditError(f"mirror map of {len(mirror)} faces for a selection of {self.num_faces}")
        w = torch.zeros(self.num_faces)
        w[mirror[self.faces]] = self.face_weights()
        return Selection.from_mask(w > 0, w)

    def symmetric(self, mirror: torch.Tensor) -> Selection:
        """This selection united with its mirror image (weights by maximum)."""
        return self.union(self.mirrored(mirror))

    # -- file -----------------------------------------------------------------------------------------
    def save(self, path, body_model: str) -> None:
        save_selection(path, self.faces.numpy(), body_model, self.num_faces,
                       None if self.weights is None else self.weights.numpy())


@dataclass
class SelectionFile:
    body_model: str
    num_faces: int
    faces: np.ndarray  # [K] int64 sorted face ids
    weights: np.ndarray | None = None  # [K] float32, soft selections only


def save_selection(path: str | Path, face_ids, body_model: str, num_faces: int, weights=None) -> None:
    """Write the selection as JSON, atomically (a crash leaves the old file or the new one)."""
    from gma.core.atomic import atomic_write_json

    ids = np.asarray(face_ids, np.int64).reshape(-1)
    ids, order = np.unique(ids, return_index=True)  # sorted, duplicates dropped
    if len(ids) and (ids[0] < 0 or ids[-1] >= num_faces):
        raise ValueError(f"selection holds face ids outside [0, {num_faces})")
    data = {"format": FORMAT, "version": 1, "body_model": body_model, "num_faces": int(num_faces),
            "faces": ids.tolist()}
    if weights is not None:
        data["weights"] = np.asarray(weights, np.float32).reshape(-1)[order].tolist()
    atomic_write_json(path, data)


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
        if "weights" in data:
            sel.weights = np.asarray(data["weights"], np.float32)
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: malformed selection file ({exc})") from exc
    if sel.faces.ndim != 1 or (len(sel.faces) and (sel.faces.min() < 0 or sel.faces.max() >= sel.num_faces)):
        raise ValueError(f"{path}: face ids must be a list within [0, {sel.num_faces})")
    if sel.weights is not None and sel.weights.shape != sel.faces.shape:
        raise ValueError(f"{path}: \"weights\" must have one entry per face id")
    if body_model is not None and sel.body_model != body_model:
        raise ValueError(f"{path}: selection was made on body model {sel.body_model!r}, not {body_model!r}")
    if num_faces is not None and sel.num_faces != num_faces:
        raise ValueError(f"{path}: selection was made on a mesh of {sel.num_faces} faces, this one has {num_faces}")
    return sel
