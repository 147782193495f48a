"""``Editor``: an editing session on one avatar — the object both ``gma edit`` and the viewer's tools
drive. It owns the avatar, its decoded fine surfels and the undo/redo stacks; every operation takes a
:class:`Selection`, writes new features for the touched faces only, appends a history record (old rows
of the touched faces) and returns a :class:`Change` that names the surfel rows to rewrite on the GPU.

    ed = Editor(avatar, body, ctx)
    view = ed.named_view("front", 256, 256)               # camera + ID render of the canonical pose
    sel = Selection.brush(view, (128, 100), 20)           # or box / lasso / wand / regions / file
    ch = ed.paint(sel, "#c03030")                         # ch.rows: surfels changed in ed.decoded
    renderer.update_rows(ch.rows, mesh=ch.mesh)           # AvatarRenderer: upload those rows only
    ed.undo(); ed.redo(); ed.avatar.save(path)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import torch

from gma.edit.errors import EditError
from gma.edit.history import apply_values, make_record, record_face_ids, restore_record
from gma.edit.invert import InvertConfig
from gma.edit.limits import MAX_COLOR_TOLERANCE, MAX_SCREEN_PIXELS, MAX_TEX_TOLERANCE, check_number, check_pixel
from gma.edit.paint import paint_features, parse_color
from gma.edit.screen import ScreenView
from gma.edit.selection import FaceGraph, Selection, mirror_map
from gma.edit.stamp import StampPlacement, resolve_placement, stamp_targets
from gma.edit.transfer import WHAT, check_shared_decoders, transfer_features
from gma.edit.views import named_view, posed_vertices

__all__ = ["Change", "Editor"]

WAND_TOLERANCE = {"color": MAX_COLOR_TOLERANCE, "tex": MAX_TEX_TOLERANCE}  # the largest tolerance by mode


@dataclass
class Change:
    """What one operation (or its undo / redo) changed. ``faces`` [M] touched face ids; ``rows`` [M·N_k]
    rows of ``Editor.decoded`` (and of the GPU surfel buffers) that changed; ``mesh``: the mesh layer's
    vertex offsets changed (re-upload the rest vertices); ``body``: shape or expression changed;
    ``record`` the history record; ``info`` solver details (iterations, transfer mode, timings)."""

    op: str
    faces: torch.Tensor
    rows: torch.Tensor
    mesh: bool = False
    body: bool = False
    record: dict | None = None
    info: dict = field(default_factory=dict)


class Editor:
    """Editing session. ``avatar``: an Avatar (edited in place); ``body``: its body model (default: loaded
    from the id in the avatar); ``ctx``: GPU context for face-ID renders (default: the shared one, made
    on first use); ``decoded``: the avatar's decoded fine surfels if the caller already has them (shared,
    updated in place — pass the viewer's own so its buffers and this session agree)."""

    def __init__(self, avatar, body=None, ctx=None, decoded=None, invert: InvertConfig | None = None):
        if avatar.model.direct:
            raise EditError("a 'direct' avatar has no features or decoders to edit")
        if body is None:
            from gma.body import load_body

            body = load_body(avatar.body_name)
        self.avatar, self.body, self._ctx = avatar, body, ctx
        self.decoded = decoded if decoded is not None else avatar.decode("fine")
        self.invert = invert or InvertConfig()
        self._redo: list[tuple[dict, dict[str, torch.Tensor], dict | None]] = []
        self._graph: FaceGraph | None = None
        self._mirror: torch.Tensor | None = None
        self._ids = None

    # -- context --------------------------------------------------------------------------------------
    @property
    def model(self):
        return self.avatar.model

    @property
    def num_faces(self) -> int:
        return self.model.num_faces

    @property
    def graph(self) -> FaceGraph:
        if self._graph is None:
            self._graph = FaceGraph(self.body.faces)
        return self._graph

    @property
    def mirror_map(self) -> torch.Tensor:
        """[F] each face's mirror face across the body's left-right plane (:func:`mirror_map` of the
        avatar's body shape); EditError when the body mesh is not left-right symmetric."""
        if self._mirror is None:
            self._mirror = mirror_map(self.body, self.avatar.shape)
        return self._mirror

    @property
    def can_redo(self) -> bool:
        return bool(self._redo)

    def _id_renderer(self):
        if self._ids is None:
            from gma.gpu import get_context
            from gma.render.face_id import FaceIdRenderer

            self._ctx = self._ctx or get_context()
            self._ids = FaceIdRenderer(self._ctx, self.body.faces.numpy())
        return self._ids

    def params(self, params: dict | None = None) -> dict:
        """Body parameters: ``params`` completed with the avatar's shape and expression, canonical pose."""
        base = self.body.canonical_params(self.avatar.shape)
        if "expression" in self.avatar.info:
            base["expression"] = torch.tensor(self.avatar.info["expression"], dtype=torch.float32)
        return {**base, **(params or {})}

    def screen_view(self, camera, params: dict | None = None) -> ScreenView:
        """The avatar's morphed mesh posed by ``params`` (default: canonical pose) seen by ``camera``,
        with its face-ID render."""
        verts = posed_vertices(self.body, self.decoded.vertex_offsets, self.params(params))
        return ScreenView.render(self._id_renderer(), verts.numpy(), self.body.faces.numpy(), camera)

    def named_view(self, name: str, width: int = 512, height: int = 512) -> ScreenView:
        """Front / back / left / right view of the canonical pose (see :mod:`gma.edit.views`)."""
        verts = posed_vertices(self.body, self.decoded.vertex_offsets, self.params())
        cam = named_view(name, verts.numpy(), self.body.up_axis, width, height)
        return ScreenView.render(self._id_renderer(), verts.numpy(), self.body.faces.numpy(), cam, name)

    def face_colors(self) -> torch.Tensor:
        """[F, 3] mean decoded colour of each face."""
        return self.decoded.colors.reshape(self.num_faces, -1, 3).mean(1)

    def wand(self, view: ScreenView, x: float, y: float, tolerance: float = 0.1, by: str = "color") -> Selection:
        """Magic wand from the face shown at pixel (x, y) of ``view``: by "color" (mean decoded colour,
        Euclidean RGB distance) or "tex" (f_tex, distance relative to the median feature norm)."""
        x, y = check_pixel("wand pixel", (x, y))
        if by in WAND_TOLERANCE:
            check_number(f"wand tolerance (by {by})", tolerance, 0.0, WAND_TOLERANCE[by])
        seed = view.face_at(x, y)
        if seed < 0:
            raise EditError(f"the wand pixel ({x:g}, {y:g}) shows no face of the avatar")
        if by == "color":
            values = self.face_colors().numpy()
        elif by == "tex":
            f = self.model.f_tex.detach()
            values = (f / f.norm(dim=1).median().clamp_min(1e-12)).numpy()
        else:
            raise EditError(f"wand compares 'color' or 'tex', got {by!r}")
        return Selection.wand(self.graph, values, seed, tolerance)

    # -- operations -----------------------------------------------------------------------------------
    def paint(self, selection: Selection, color, surfel_weights=None) -> Change:
        """Paint the selected faces with ``color`` (anything :func:`parse_color` reads, or [M, 3] /
        [M, N_k, 3] per face / surfel), weighted by the selection's soft weights (times
        ``surfel_weights`` [M, N_k] if given)."""
        sel = selection.require()
        per_surfel = not isinstance(color, str) and np.asarray(color).ndim > 1
        col = np.asarray(color, np.float32) if per_surfel else np.asarray(parse_color(color), np.float32)
        w = sel.face_weights()[:, None].expand(-1, self.model.config.fine_per_face)
        if surfel_weights is not None:
            w = w * torch.as_tensor(np.asarray(surfel_weights, np.float32))
        new, info = paint_features(self.model, sel.faces, col, w, self.invert)
        params = {"color": "per-surfel" if per_surfel else [round(float(c), 6) for c in col],
                  "soft": sel.soft or surfel_weights is not None}
        return self._commit("paint", params, sel.faces, {"f_tex": new}, info={"iterations": info["iterations"]})

    def stamp(self, image: np.ndarray, view: ScreenView, placement: StampPlacement | None = None,
              selection: Selection | None = None, name: str = "image") -> Change:
        """Stamp ``image`` [h, w, 4] RGBA seen from ``view`` (see :mod:`gma.edit.stamp`), restricted to
        ``selection`` when given (its weights scale the alpha)."""
        from gma.body.placement import place_surfels

        placement = placement or StampPlacement()
        nk = self.model.config.fine_per_face
        if selection is not None:
            cand, face_weights = selection.require().faces, selection.face_weights()
        else:
            cand, face_weights = torch.arange(self.num_faces), None
        # Only faces near the image's footprint can be hit: placing and projecting every surfel of the
        # body would cost more than the solve.
        cx, cy, size_px = resolve_placement(view, placement, cand)
        if size_px > MAX_SCREEN_PIXELS:  # a size in metres, seen from very close
            raise EditError(f"the stamp would be {size_px:.0f} px wide in this view (at most {MAX_SCREEN_PIXELS:.0f}): "
                            "give a smaller size or a camera further away")
        ih, iw = image.shape[:2]
        reach = 0.5 * size_px * math.hypot(ih, iw) / max(ih, iw) + 4.0  # half-diagonal + a surfel's spread
        near = torch.from_numpy(np.hypot(view.px[cand.numpy(), 0] - cx, view.px[cand.numpy(), 1] - cy) <= reach)
        cand = cand[near]
        if face_weights is not None:
            face_weights = face_weights[near]  # the selection's weights follow the faces kept
        if len(cand) == 0:
            raise EditError("the stamp covers no visible surfel of the selection (check the view, centre and size)")
        asked, placement = placement, StampPlacement((cx, cy), size_px, "px", placement.rotation)
        rows = (cand[:, None] * nk + torch.arange(nk)).reshape(-1)
        b = self.decoded.binding
        sub = b.select(rows)
        with torch.no_grad():
            means, _, _ = place_surfels(torch.as_tensor(view.vertices), self.body.faces, sub)
        sw = None if face_weights is None else face_weights.repeat_interleave(nk)
        tol = self.model.config.fine_offset_max + 0.005
        colors, weights, _ = stamp_targets(view, means, sub.face_id, image, placement, sw, tol)
        weights = torch.from_numpy(weights).reshape(-1, nk)
        weights[weights <= 1 / 255] = 0  # below one 8-bit step: leave the surfel (and maybe its face) alone
        hit = weights.sum(1) > 0
        if not bool(hit.any()):
            raise EditError("the stamp covers no visible surfel of the selection (check the view, centre and size)")
        faces = cand[hit]
        new, info = paint_features(self.model, faces, torch.from_numpy(colors).reshape(-1, nk, 3)[hit],
                                   weights[hit], self.invert)
        params = {"image": name, "view": view.name or "camera",
                  "camera": view.camera.to_json() | {"K": np.asarray(view.camera.K).round(6).tolist(),
                                                     "w2c": np.asarray(view.camera.viewmat).round(6).tolist()},
                  "centre": None if asked.centre is None else [float(v) for v in asked.centre],
                  "size": asked.size, "unit": asked.unit, "rotation": asked.rotation}
        return self._commit("stamp", params, faces, {"f_tex": new}, info={"iterations": info["iterations"]})

    def transfer(self, donor, selection: Selection, what: str = "tex", mode: str = "auto",
                 donor_name: str = "donor", target_name: str = "target") -> Change:
        """Copy (same body shape) or fit (other shape) ``what`` (tex, geo, both) of the selected faces
        from ``donor`` (an Avatar sharing this one's decoders); see :mod:`gma.edit.transfer`."""
        sel = selection.require()
        if what not in WHAT:
            raise EditError(f"transfer what must be one of {', '.join(WHAT)}, got {what!r}")
        check_shared_decoders(self.model, donor.model, target_name, donor_name)
        new, info = transfer_features(self.model, donor.model, sel.faces, what, mode, self.invert)
        params = {"donor": donor_name, "what": what, "mode": info["mode"]}
        return self._commit("transfer", params, sel.faces, new, info=info)

    def check_body(self, shape=None, expression=None) -> tuple[torch.Tensor | None, torch.Tensor | None]:
        """``shape`` [S] and ``expression`` [E] (either may be None) as float tensors, after checking
        them against the body's parameter spaces: the right size, finite, in range. EditError names the
        bad entry and its range (Anny: every phenotype and facial-action value in [0, 1])."""
        out = []
        for name, value in (("shape", shape), ("expression", expression)):
            if value is None:
                out.append(None)
                continue
            try:
                t = torch.as_tensor(np.asarray(value, np.float32))
                if t.dim() != 1:
                    raise ValueError(f"{name} must be a list of {self.body.param_spaces[name].size} numbers")
                self.body.param_spaces[name].check_values(t)
            except (ValueError, TypeError) as exc:
                raise EditError(f"bad body {name}: {exc}") from None
            out.append(t)
        return out[0], out[1]

    def set_body(self, shape=None, expression=None) -> Change:
        """Set the avatar's body shape [S] and / or default expression [E] (saved with it; the PE and
        mesh-layer directions stay those of the fitted identity, so the decoders see what they learnt).
        Values are checked first (:meth:`check_body`)."""
        values, info, params = {}, {}, {}
        old_info = {}
        s, e = self.check_body(shape, expression)
        if s is not None:
            values["shape"] = s
            params["shape"] = [float(v) for v in s]
        if e is not None:
            info["expression"] = [float(v) for v in e]
            old_info["expression"] = self.avatar.info.get("expression")
            params["expression"] = info["expression"]
        if not params:
            raise EditError("set_body needs a shape or an expression")
        old = {"shape": self.avatar.shape.clone()} if "shape" in values else {}
        rec = make_record("body", params, None, old, old_info or None)
        apply_values(self.avatar, None, values, info)
        self.avatar.history.append(rec)
        self._redo.clear()
        return Change("body", torch.zeros(0, dtype=torch.long), torch.zeros(0, dtype=torch.long), body=True,
                      record=rec)

    # -- history --------------------------------------------------------------------------------------
    def _commit(self, op: str, params: dict, faces: torch.Tensor, new: dict[str, torch.Tensor],
                info: dict | None = None) -> Change:
        faces = torch.as_tensor(faces, dtype=torch.long)
        old = {name: getattr(self.model, name)[faces].detach().clone() for name in new}
        rec = make_record(op, params, faces, old)
        apply_values(self.avatar, faces, new)
        self.avatar.history.append(rec)
        self._redo.clear()
        return self._redecode(op, faces, "f_geo" in new, rec, info)

    def _redecode(self, op, faces, mesh: bool, rec=None, info=None, body: bool = False) -> Change:
        if faces is None or len(faces) == 0:
            return Change(op, torch.zeros(0, dtype=torch.long), torch.zeros(0, dtype=torch.long), body=body,
                          record=rec, info=info or {})
        rows = self.model.redecode_faces(self.decoded, faces, mesh=mesh)
        return Change(op, faces, rows, mesh=mesh, body=body, record=rec, info=info or {})

    def undo(self) -> Change:
        """Undo the newest history record (also one loaded from the file)."""
        if not self.avatar.history:
            raise EditError("nothing to undo: the avatar's history is empty")
        rec = self.avatar.history[-1]
        new_info = {k: self.avatar.info.get(k) for k in rec.get("old_info") or {}}
        current = restore_record(self.avatar, rec)
        self.avatar.history.pop()
        self._redo.append((rec, current, new_info or None))
        faces = record_face_ids(rec)
        mesh = "f_geo" in rec.get("old", {})
        return self._redecode("undo " + rec["op"], faces, mesh, rec, body=faces is None)

    def redo(self) -> Change:
        """Re-apply the newest undone record (within this session)."""
        if not self._redo:
            raise EditError("nothing to redo")
        rec, values, info = self._redo.pop()
        faces = record_face_ids(rec)
        apply_values(self.avatar, faces, values, info)
        self.avatar.history.append(rec)
        return self._redecode("redo " + rec["op"], faces, any(k == "f_geo" for k in values), rec,
                              body=faces is None)

    def revert(self, index: int) -> list[Change]:
        """Undo records until only the first ``index`` remain (``revert(0)``: back to the fitted avatar)."""
        n = len(self.avatar.history)
        if not 0 <= index <= n:
            raise EditError(f"cannot revert to record {index}: the history holds {n} records")
        return [self.undo() for _ in range(n - index)]


def summarize(rec: dict) -> str:
    """One line describing a history record (``gma edit --history``)."""
    p = rec.get("params", {})
    detail = ", ".join(f"{k}={v}" for k, v in p.items() if k != "camera")
    faces = f"{rec['faces']} faces" if "faces" in rec else "body"
    fields = ",".join(rec.get("old", {})) or ",".join(rec.get("old_info", {}))
    return f"{rec.get('op', '?'):9s} {faces:>12s}  [{fields}]  {detail}"


