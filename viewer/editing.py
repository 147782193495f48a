"""The viewer's edit tools, without a window: selection (box, lasso, brush, wand, regions, grow/shrink,
invert), paint (fill, brush strokes, eyedropper), stamp (image, placement, apply), transfer (donor
avatar), body shape "keep", history (undo / redo / revert) and save.

Every mouse gesture of the window and every panel widget calls a method here, in pixel coordinates of
the current view, so tests and the benchmark drive exactly the code the mouse drives. All edits go
through :class:`gma.edit.Editor` (the only place edits happen); a :class:`gma.edit.Change` is applied to
the GPU by rewriting its rows only (:meth:`gma.view.source.BodySource.update_rows`): no full re-upload,
no new pipelines, and the frame loop (animation included) keeps running between and during strokes.

Feature solves take from tens of milliseconds to a second on a loaded 2-core CPU, longer than a frame.
With ``background`` (the window's setting) an edit runs on a worker thread: its target colours are
written to the touched rows of the GPU colour buffer at once (a preview, visible on the next frame; the
window starts the solve only after presenting that frame, so the two do not share the CPU), the frame
loop and the animation go on, and :meth:`EditTools.poll` (once per frame) uploads the decoded
result when the solve is done. One edit runs at a time; every action that reads or writes the avatar
waits for it first, so the editor is never used from two threads at once. Tests and scripts that call
the tools directly use the same code with ``background=False`` or call :meth:`EditTools.wait`.

Selections are made in a :class:`gma.edit.ScreenView` of what is on screen now (the posed mesh seen by
the current camera, with a face-ID render so that only visible faces are hit). The view is cached until
the camera, the window size or the pose changes, so a brush stroke renders IDs once, not per dab.
"""

from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from gma.core.errors import GmaError, InputError
from gma.edit import EditError, Editor, ScreenView, Selection, StampPlacement, load_stamp_image, mirror_map, parse_color
from gma.edit.editor import summarize
from gma.edit.history import make_record, record_face_ids, record_old

__all__ = ["BrushSettings", "EditTools", "StampState", "StrokeStats"]


@dataclass
class BrushSettings:
    """Circular brush: ``radius`` in pixels, ``falloff`` the soft fraction of the radius (0: hard edge)."""

    radius: float = 20.0
    falloff: float = 0.5


@dataclass
class StampState:
    """The image being placed and where: ``centre`` (x, y) pixels of the current view (None: the view's
    centre), ``size`` of the image's longer side in pixels, ``rotation`` degrees counter-clockwise."""

    image: np.ndarray  # [h, w, 4] float32 RGBA
    name: str
    centre: tuple[float, float] | None = None
    size: float = 80.0
    rotation: float = 0.0
    version: int = 0  # bumped when the image changes (the renderer re-uploads its preview texture)

    def corners(self, width: int, height: int) -> np.ndarray:
        """[4, 2] pixel corners of the preview quad (top-left, top-right, bottom-right, bottom-left of the
        image), rotated like :func:`gma.edit.stamp.stamp_targets` samples it."""
        cx, cy = self.centre if self.centre is not None else (width / 2, height / 2)
        ih, iw = self.image.shape[:2]
        s = self.size / max(ih, iw)
        hw, hh = iw * s / 2, ih * s / 2
        a = math.radians(self.rotation)
        # stamp_targets maps screen offsets to image offsets by R(a); the image's corners go back by R(-a).
        c, si = math.cos(a), math.sin(a)
        local = np.array([[-hw, -hh], [hw, -hh], [hw, hh], [-hw, hh]])
        rot = np.array([[c, si], [-si, c]])
        return (local @ rot.T + [cx, cy]).astype(np.float32)


@dataclass
class StrokeStats:
    """Timings of the current / last brush stroke (for the panel and the benchmark)."""

    dabs: int = 0
    updates: int = 0
    faces: int = 0
    update_ms: list[float] = field(default_factory=list)


class EditTools:
    """Edit tools on a viewer ``state`` (:class:`viewer.state.ViewerState`) whose source is bound to a
    body. Editing features needs an avatar source (``source.avatar``); selection works on any body."""

    def __init__(self, state, background: bool = False):
        self.state = state
        self.background = background  # run edits on a worker thread (see the module doc)
        self._job: dict | None = None
        self.source = state.source
        self.body = self.source.body
        self.selection = Selection(torch.zeros(0, dtype=torch.long), self.body.num_faces)
        self.brush = BrushSettings()
        self.color = (0.75, 0.19, 0.19)
        self.wand_tolerance = 0.1
        self.mirror = False  # selections and paint strokes also take their mirror image (left-right)
        self.stamp: StampState | None = None
        self.stamp_in_selection = False  # restrict the stamp to the selection
        self.donor = None  # the donor Avatar of a transfer
        self.donor_name = ""
        self.donor_thumbnail: np.ndarray | None = None  # [h, w, 4] uint8 render of the donor
        self.transfer_what = "tex"
        self.version = 0  # edits applied (including undo / redo)
        self.saved_mark = self._history_mark()  # the history as last saved (or opened)
        self.last_change_ms = 0.0
        self.stroke: StrokeStats | None = None
        self.last_stroke = StrokeStats()
        self._pending: list[tuple[float, float]] = []
        self._last_dab: tuple[float, float] | None = None
        self._stroke_start = 0
        self._stroke_mode = "paint"
        self._stroke_size = (1, 1)
        self._ending = False
        self._view: ScreenView | None = None
        self._view_key = None
        self._ids = None
        self._editor: Editor | None = None
        self._mirror_map: torch.Tensor | None = None

    # -- context --------------------------------------------------------------------------------------
    @property
    def avatar(self):
        return getattr(self.source, "avatar", None)

    @property
    def can_edit(self) -> bool:
        return self.avatar is not None

    @property
    def editor(self) -> Editor:
        """The editing session on the source's avatar, sharing the source's decoded surfels."""
        if self._editor is None:
            if self.avatar is None:
                raise InputError("editing needs a fitted avatar (.gma); this source only shows a body")
            if self.avatar.render_layer != "fine":  # the source holds one coarse surfel per face
                raise InputError("this avatar shows its coarse layer (mesh_only); the edit tools need fine surfels")
            self._editor = Editor(self.avatar, self.body, self.state.ctx, decoded=self.source.decoded)
        return self._editor

    def _history_mark(self) -> tuple:
        """What identifies the avatar's state: its history's length and newest record (undo back to the
        saved state restores both, so the file is clean again; any new edit adds or replaces a record)."""
        history = self.avatar.history if self.avatar is not None else []
        return len(history), id(history[-1]) if history else None

    @property
    def dirty(self) -> bool:
        return self.avatar is not None and self._history_mark() != self.saved_mark

    @property
    def path(self) -> Path | None:
        return getattr(self.source, "path", None)

    def view(self, size: tuple[int, int]) -> ScreenView:
        """What is on screen now for a ``size`` = (w, h) frame: camera, posed mesh and face-ID render
        (cached until the camera, the size or the pose changes)."""
        cam = self.state.camera(*size)
        key = (cam.viewmat.tobytes(), cam.K.tobytes(), cam.width, cam.height, self.source.pose_version)
        if key != self._view_key:
            if self._ids is None:
                from gma.render.face_id import FaceIdRenderer

                self._ids = FaceIdRenderer(self.state.ctx, self.body.faces.numpy())
            self._view = ScreenView.render(self._ids, self.source.posed_vertices(), self.body.faces.numpy(), cam)
            self._view_key = key
        return self._view

    # -- selection ------------------------------------------------------------------------------------
    def _mirrored(self, sel: Selection) -> Selection:
        """``sel`` united with its mirror image when the mirror toggle is on."""
        if not self.mirror or len(sel) == 0:
            return sel
        if self._mirror_map is None:
            try:
                self._mirror_map = mirror_map(self.body, getattr(self.avatar, "shape", None))
            except EditError:
                self.mirror = False  # the toggle goes back off; the message becomes the status line
                raise
        return sel.symmetric(self._mirror_map)

    def set_selection(self, sel: Selection, mode: str = "replace") -> Selection:
        """Combine ``sel`` (with its mirror image when the mirror toggle is on) with the current
        selection (replace, add, subtract) and show it."""
        sel = self._mirrored(sel)
        if mode == "add":
            sel = self.selection.union(sel)
        elif mode == "subtract":
            sel = self.selection.subtract(sel)
        elif mode != "replace":
            raise InputError(f"selection mode must be replace, add or subtract, not {mode!r}")
        self.selection = sel
        self.state.scene.set_selection(sel.faces.numpy())
        return sel

    def select_box(self, box, size, mode: str = "replace") -> Selection:
        return self.set_selection(Selection.box(self.view(size), box), mode)

    def select_lasso(self, polygon, size, mode: str = "replace") -> Selection:
        return self.set_selection(Selection.lasso(self.view(size), np.asarray(polygon, np.float64)), mode)

    def select_brush(self, centre, size, mode: str = "add") -> Selection:
        sel = Selection.brush(self.view(size), centre, self.brush.radius, self.brush.falloff)
        return self.set_selection(sel, mode)

    def select_wand(self, x: float, y: float, size, mode: str = "replace") -> Selection:
        self.wait()  # the wand reads the decoded colours
        return self.set_selection(self.editor.wand(self.view(size), x, y, self.wand_tolerance), mode)

    def select_region(self, name: str, mode: str = "replace") -> Selection:
        return self.set_selection(Selection.from_regions(self.body, name), mode)

    def select_unseen(self, mode: str = "replace") -> Selection:
        """The faces the fit's frames never showed (filled in): with the selection highlight, the seen /
        guessed overlay; then paint or transfer them like any selection."""
        if self.avatar is None:
            raise EditError("only an avatar records what its training frames saw")
        return self.set_selection(Selection.unseen(self.avatar), mode)

    def grow(self, rings: int = 1) -> Selection:
        return self.set_selection(self.selection.grow(self._graph(), rings))

    def shrink(self, rings: int = 1) -> Selection:
        return self.set_selection(self.selection.shrink(self._graph(), rings))

    def invert(self) -> Selection:
        return self.set_selection(self.selection.invert())

    def clear(self) -> Selection:
        return self.set_selection(Selection(torch.zeros(0, dtype=torch.long), self.body.num_faces))

    def _graph(self):
        if self._editor is not None:
            return self._editor.graph
        if not hasattr(self, "_face_graph"):
            from gma.edit import FaceGraph

            self._face_graph = FaceGraph(self.body.faces)
        return self._face_graph

    # -- what the tools draw over the frame -------------------------------------------------------------
    def overlays(self, size, tool: str, cursor=None) -> tuple[list[np.ndarray], list]:
        """(lines, images) to draw over the frame for ``tool`` with the cursor at ``cursor`` (pixels): the
        brush circle, the stamp preview quad, the donor thumbnail. Pure geometry: no GPU work here."""
        from gma.view import ScreenImage

        lines, images = [], []
        w, h = size
        if tool in ("brush", "paint") and cursor is not None:
            a = np.linspace(0, 2 * np.pi, 33)
            r = self.brush.radius
            lines.append(np.c_[cursor[0] + r * np.cos(a), cursor[1] + r * np.sin(a)].astype(np.float32))
            if self.brush.falloff > 0:
                r *= 1 - self.brush.falloff
                lines.append(np.c_[cursor[0] + r * np.cos(a), cursor[1] + r * np.sin(a)].astype(np.float32))
        if tool == "stamp" and self.stamp is not None:
            c = self.stamp.corners(w, h)
            images.append(ScreenImage(self.stamp.image, c, ("stamp", id(self.stamp.image)), 0.75))
            lines.append(np.r_[c, c[:1]])
        if self.donor_thumbnail is not None:
            th, tw = self.donor_thumbnail.shape[:2]
            s = min(1.0, 0.3 * h / th)
            x0, y0 = w - tw * s - 4, h - th * s - 4
            corners = np.array([[x0, y0], [x0 + tw * s, y0], [x0 + tw * s, y0 + th * s], [x0, y0 + th * s]],
                               np.float32)
            images.append(ScreenImage(self.donor_thumbnail, corners, ("donor", id(self.donor_thumbnail))))
            lines.append(np.r_[corners, corners[:1]])
        return lines, images

    # -- applying changes -----------------------------------------------------------------------------
    def apply(self, change) -> None:
        """Show a :class:`gma.edit.Change` (or a list of them): rewrite the touched rows on the GPU."""
        changes = change if isinstance(change, list) else [change]
        rows = [c.rows for c in changes if len(c.rows)]
        mesh = any(c.mesh for c in changes)
        if rows or mesh:
            all_rows = torch.cat(rows) if rows else torch.zeros(0, dtype=torch.long)
            self.source.update_rows(all_rows, self.source.decoded.colors, mesh=mesh)
        if any(c.body for c in changes) and self.state.controls is not None:
            self.reset_body()
        self.version += 1

    def reset_body(self) -> None:
        """After a body edit, or its undo: the sliders show the avatar's shape and expression."""
        ctl, av = self.state.controls, self.avatar
        ctl.shape = av.shape.clone()
        if "expression" in av.info:
            ctl.expression = torch.tensor(av.info["expression"], dtype=torch.float32)
        else:
            ctl.expression = ctl.expression_space.default_tensor()
        ctl.apply()

    def _run(self, what: str, fn, preview: tuple | None = None, after=None):
        """Run one edit ``fn`` (returning a Change or a list), apply it, time it and report it in the
        status line; ``preview`` (selection, colour) is shown at once; ``after`` runs (on this thread)
        once the change is applied. In the background: returns None at once, see :meth:`poll`."""
        self._join()
        t0 = time.perf_counter()
        if preview is not None:
            self._preview(*preview)
        job = {"what": what, "t0": t0, "after": after, "change": None, "error": None}
        if not self.background:
            job["change"] = fn()
            return self._finish(job)

        def work():
            try:
                job["change"] = fn()
            except Exception as exc:  # handed to the frame loop's poll(), which reports it
                job["error"] = exc

        job["thread"] = threading.Thread(target=work, name=f"gma-edit-{what}", daemon=True)
        job["started"] = False  # started by start() once the preview frame is submitted (or by poll)
        self._job = job
        self.state.message = f"{what}..."
        return None

    def _finish(self, job: dict):
        change = job["change"]
        self.apply(change)
        self.last_change_ms = (time.perf_counter() - job["t0"]) * 1e3
        n = sum(len(c.faces) for c in change) if isinstance(change, list) else len(change.faces)
        self.state.message = f"{job['what']}: {n} faces in {self.last_change_ms:.0f} ms"
        if job["after"] is not None:
            job["after"]()
        return change

    @property
    def busy(self) -> bool:
        """An edit is running on the worker thread."""
        return self._job is not None

    def start(self) -> None:
        """Start the queued background solve. The window calls this after presenting a frame, so the
        frame showing an edit's preview is drawn before the solve competes with it for the CPU."""
        job = self._job
        if job is not None and not job["started"]:
            job["started"] = True
            job["thread"].start()

    def poll(self, start: bool = True):
        """Apply the background edit if it has finished (call once per frame). Returns its change, or
        None; a failed edit raises its error here (and its preview is taken back)."""
        job = self._job
        if job is not None and start:
            self.start()
        if job is None or not job["started"] or job["thread"].is_alive():
            return None
        self._job = None
        if job["error"] is not None:
            self._unpreview()
            raise job["error"]
        return self._finish(job)

    def _join(self):
        """Wait for the running background edit, if any, and apply it."""
        if self._job is not None:
            self.start()
            self._job["thread"].join()
            return self.poll()
        return None

    def wait(self) -> None:
        """Wait until every edit asked for has landed (the running one, and the rest of a finished
        brush stroke)."""
        while True:
            if self._job is not None:
                self._join()
            elif self.stroke is not None and self._ending:
                self.stroke_update(self._stroke_size)  # submits the stroke's last dabs, or merges it
            else:
                return

    def _preview(self, sel: Selection, color) -> None:
        """Write the paint target (blended by the selection's weights) into the GPU colour rows of the
        selected faces now; the solved colours replace it when the edit lands."""
        if len(sel) == 0 or not self.can_edit:
            return
        nk = self.avatar.config.fine_per_face
        rows = (sel.faces[:, None] * nk + torch.arange(nk)).reshape(-1)
        w = sel.face_weights().repeat_interleave(nk)[:, None]
        colors = self.source.decoded.colors
        col = colors[rows] * (1 - w) + torch.as_tensor(np.asarray(color, np.float32)) * w
        lo, hi = int(rows.min()), int(rows.max()) + 1
        if len(rows) < hi - lo and int((torch.diff(rows.sort().values) != 1).sum()) > 256:
            span = colors[lo:hi].clone()  # scattered rows: one write of the span, not thousands
            span[rows - lo] = col
            self.source.write_colors(np.arange(lo, hi), span.numpy())
        else:
            self.source.write_colors(rows.numpy(), col.numpy())
        self._previewed = rows

    def _unpreview(self) -> None:
        rows = getattr(self, "_previewed", None)
        if rows is not None:
            self.source.write_colors(rows.numpy(), self.source.decoded.colors[rows].numpy())
            self._previewed = None

    # -- paint ----------------------------------------------------------------------------------------
    def set_color(self, color) -> tuple[float, float, float]:
        """Set the paint colour: RGB in [0, 1], a hex string or a colour name (see parse_color)."""
        if isinstance(color, str):
            color = parse_color(color)
        self.color = tuple(float(min(max(c, 0.0), 1.0)) for c in color)
        return self.color

    @property
    def hex_color(self) -> str:
        return "#" + "".join(f"{round(c * 255):02x}" for c in self.color)

    def fill(self):
        """Paint the whole selection with the current colour (soft weights blend at its edges)."""
        sel, color, editor = self.selection, self.color, self.editor
        sel.require()
        return self._run("paint", lambda: editor.paint(sel, color), preview=(sel, color))

    def pick_color(self, x: float, y: float, size) -> tuple[float, float, float]:
        """Eyedropper: the colour of the rendered frame at pixel (x, y), without the selection overlay.
        One offscreen render and readback on the click, never in the frame loop."""
        w, h = size
        ix, iy = int(x), int(y)
        if not (0 <= ix < w and 0 <= iy < h):
            raise InputError(f"eyedropper pixel ({x:.0f}, {y:.0f}) is outside the {w}x{h} view")
        opts = self.state.scene.options
        shown, opts.selection = opts.selection, False
        try:
            img = self.state.renderer.render_image(self.state.scene, self.state.camera(w, h))
        finally:
            opts.selection = shown
        return self.set_color(img[iy, ix, :3].astype(np.float32) / 255.0)

    # -- brush strokes (paint, or select while dragging) -------------------------------------------------
    def stroke_begin(self, x: float, y: float, mode: str = "paint") -> None:
        """Start a brush stroke at (x, y): ``mode`` "paint" paints, "select" adds to the selection,
        "deselect" removes from it. Dabs are applied by :meth:`stroke_update` (once per frame)."""
        self.wait()
        if mode == "paint":
            self.editor  # noqa: B018 - fail on press, not in the middle of the stroke
        self._stroke_mode = mode
        self._stroke_start = len(self.avatar.history) if self.avatar is not None else 0
        self.stroke = StrokeStats()
        self._stroke_color = self.color
        self._stroke_todo: Selection | None = None  # dabs shown as preview, not solved yet
        self._ending = False  # released: solve what is left, then fold the stroke into one record
        self._pending = [(x, y)]
        self._last_dab = None

    def stroke_to(self, x: float, y: float) -> None:
        """The cursor moved during the stroke (cheap: queued for the next :meth:`stroke_update`)."""
        if self.stroke is not None:
            self._pending.append((x, y))

    def _dab_points(self) -> list[tuple[float, float]]:
        """Queued cursor positions resampled every third of the radius along the path (no gaps in a
        fast stroke, no redundant dabs in a slow one)."""
        step = max(self.brush.radius / 3, 1.0)
        out = []
        last = self._last_dab
        for p in self._pending:
            if last is None:
                out.append(p)
                last = p
                continue
            d = math.hypot(p[0] - last[0], p[1] - last[1])
            n = int(d // step)
            for i in range(1, n + 1):
                t = i * step / d
                out.append((last[0] + t * (p[0] - last[0]), last[1] + t * (p[1] - last[1])))
            if n:
                last = out[-1]
        self._pending = []
        if out:
            self._last_dab = out[-1]
        return out

    def stroke_update(self, size) -> bool:
        """Apply the dabs queued since the last call (the union of their brush discs, weights by
        maximum). Called once per frame while dragging; True when the frame changed. In the background
        the dabs are shown as a preview at once and solved together when the previous solve is done."""
        if self.stroke is None:
            return False
        self._stroke_size = size
        landed = self._stroke_mode == "paint" and self.busy and self.poll(start=False) is not None
        if landed and self._stroke_todo is not None:
            # the landed solve rewrote rows that newer, unsolved dabs also cover: show those again
            self._preview(self._stroke_todo, self._stroke_color)
        t0 = time.perf_counter()
        pts = self._dab_points()
        sel = None
        if pts:
            view = self.view(size)
            for p in pts:
                disc = Selection.brush(view, p, self.brush.radius, self.brush.falloff)
                sel = disc if sel is None else sel.union(disc)
            self.stroke.dabs += len(pts)
        if self._stroke_mode != "paint":  # (set_selection adds the mirror image)
            if sel is not None:
                self.set_selection(sel, "add" if self._stroke_mode == "select" else "subtract")
            if self._ending:
                self.last_stroke, self.stroke = self.stroke, None
            return sel is not None
        changed = sel is not None and len(sel) > 0
        if changed:
            sel = self._mirrored(sel)
            if self.background:  # shown now; solved when the worker is free
                self._preview(sel, self._stroke_color)
            todo = self._stroke_todo
            self._stroke_todo = sel if todo is None else todo.union(sel)
        if self.busy:
            return changed
        if self._stroke_todo is None:
            if self._ending:
                self._merge_stroke()
            return changed
        todo, self._stroke_todo = self._stroke_todo, None
        self.stroke.faces += len(todo)
        self.stroke.updates += 1
        editor, color = self.editor, self._stroke_color
        self._run("paint", lambda: editor.paint(todo, color), after=self._merge_stroke if self._ending else None)
        self.stroke.update_ms.append((time.perf_counter() - t0) * 1e3)
        return True

    def stroke_end(self, size) -> None:
        """Finish the stroke: solve what is left and fold its dabs into one history record (so one
        undo takes back the whole stroke); in the background this happens when the solves land (the
        frame loop's :meth:`stroke_update` calls, or :meth:`wait`)."""
        if self.stroke is None:
            return
        self._ending = True
        self.stroke_update(size)

    def _merge_stroke(self) -> None:
        if self.stroke is None:
            return
        st, self.stroke = self.stroke, None
        self.last_stroke = st
        n = merge_records(self.avatar.history, self._stroke_start,
                          {"color": [round(c, 6) for c in self._stroke_color], "soft": True, "stroke": st.dabs})
        if n:
            ms = np.median(st.update_ms) if st.update_ms else 0.0
            self.state.message = f"paint stroke: {st.dabs} dabs, {n} faces, {ms:.0f} ms per update"

    # -- stamp ----------------------------------------------------------------------------------------
    def load_stamp(self, path) -> StampState:
        """Load an image (PNG with alpha, JPEG, ...) to place; keeps the placement of a previous one."""
        img = load_stamp_image(path)
        old = self.stamp
        self.stamp = StampState(img, Path(path).name)
        if old is not None:
            self.stamp.centre, self.stamp.size, self.stamp.rotation = old.centre, old.size, old.rotation
            self.stamp.version = old.version + 1
        self.state.message = f"stamp {Path(path).name}: {img.shape[1]}x{img.shape[0]}; drag to move, " \
                             "wheel to scale, Shift+drag to rotate, Enter to apply"
        return self.stamp

    def set_stamp_image(self, image: np.ndarray, name: str = "image") -> StampState:
        """Place an RGBA [h, w, 4] float image (e.g. :func:`gma.edit.solid_shape`)."""
        old = self.stamp
        self.stamp = StampState(np.asarray(image, np.float32), name)
        if old is not None:
            self.stamp.centre, self.stamp.size, self.stamp.rotation = old.centre, old.size, old.rotation
            self.stamp.version = old.version + 1
        return self.stamp

    def _need_stamp(self) -> StampState:
        if self.stamp is None:
            raise InputError("no stamp image: load one (file field, or drop it on the window)")
        return self.stamp

    def move_stamp(self, dx: float, dy: float, size) -> None:
        st = self._need_stamp()
        cx, cy = st.centre if st.centre is not None else (size[0] / 2, size[1] / 2)
        st.centre = (cx + dx, cy + dy)

    def scale_stamp(self, factor: float) -> None:
        st = self._need_stamp()
        st.size = float(min(max(st.size * factor, 4.0), 4096.0))

    def rotate_stamp(self, degrees: float) -> None:
        st = self._need_stamp()
        st.rotation = (st.rotation + degrees + 180.0) % 360.0 - 180.0

    def apply_stamp(self, size):
        """Stamp the placed image onto what the current view shows (visible surfels only)."""
        st = self._need_stamp()
        w, h = size
        place = StampPlacement(st.centre or (w / 2, h / 2), st.size, "px", st.rotation)
        sel = self.selection if self.stamp_in_selection else None
        view, editor = self.view(size), self.editor
        return self._run("stamp", lambda: editor.stamp(st.image, view, place, sel, st.name))

    # -- transfer -------------------------------------------------------------------------------------
    def load_donor(self, path):
        """Open a donor avatar; refused (with what differs) when it does not share this one's decoders."""
        from gma.avatar import Avatar
        from gma.edit import check_shared_decoders

        path = Path(path)
        self.wait()
        try:
            donor = Avatar.load(path, self.body)
        except FileNotFoundError as exc:
            raise InputError(str(exc)) from None
        check_shared_decoders(self.editor.model, donor.model, self.path.name if self.path else "this avatar",
                              path.name)
        self.donor, self.donor_name = donor, path.name
        self.donor_thumbnail = self._thumbnail(donor)
        self.state.message = f"donor {path.name} loaded: select faces, choose geo / tex / both, transfer"
        return donor

    def _thumbnail(self, donor, size: int = 128) -> np.ndarray:
        """A small front render of the donor, drawn once (shown in a corner of the frame)."""
        from gma.view import BodySource, FrameRenderer, OrbitCamera, Scene

        dec = donor.decode("fine")
        src = BodySource(self.state.ctx, self.body, dec.binding, dec.colors.numpy(), dec.opacities.numpy(),
                         name=self.donor_name, vertex_offsets=dec.vertex_offsets)
        src.set_params({"shape": donor.shape})
        cam = OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis).camera(size, size)
        scene = Scene(src)
        scene.options.background = self.state.scene.options.background
        return FrameRenderer(self.state.ctx).render_image(scene, cam)

    def transfer(self):
        """Copy the donor's features (``transfer_what``: geo, tex, both) onto the selected faces."""
        if self.donor is None:
            raise InputError("no donor avatar: open one in the Transfer section (or drop a .gma on the window)")
        sel, what, editor, donor = self.selection.require(), self.transfer_what, self.editor, self.donor
        name = self.path.name if self.path else "target"
        return self._run(f"transfer {what}", lambda: editor.transfer(donor, sel, what, donor_name=self.donor_name,
                                                                     target_name=name))

    # -- body -----------------------------------------------------------------------------------------
    def keep_body(self):
        """Write the Body panel's shape and expression into the avatar (undoable, saved with it)."""
        self.wait()
        ctl, editor = self.state.controls, self.editor
        # Checked here, on this thread, so a value out of the body's range is refused at once.
        shape, expr = editor.check_body(ctl.shape.clone(), ctl.expression.clone())
        return self._run("body", lambda: editor.set_body(shape=shape, expression=expr))

    # -- history --------------------------------------------------------------------------------------
    def history(self) -> list[str]:
        """One line per history record, oldest first (as of the last applied edit)."""
        return [summarize(r) for r in self.avatar.history] if self.avatar is not None else []

    @property
    def can_undo(self) -> bool:
        return self.avatar is not None and bool(self.avatar.history)

    @property
    def can_redo(self) -> bool:
        return self._editor is not None and self._editor.can_redo

    # Undo / redo restore stored rows (no solve: milliseconds), so they run on this thread.
    def undo(self):
        self.wait()
        return self._now("undo", self.editor.undo)

    def redo(self):
        self.wait()
        return self._now("redo", self.editor.redo)

    def revert(self, index: int):
        """Undo back to the first ``index`` records (0: the avatar as fitted or first saved)."""
        self.wait()
        return self._now(f"revert to {index}", lambda: self.editor.revert(index))

    def _now(self, what: str, fn):
        return self._finish({"what": what, "t0": time.perf_counter(), "after": None, "change": fn()})

    # -- file -----------------------------------------------------------------------------------------
    def save(self, path=None) -> Path:
        """Write the avatar (with its history) atomically to ``path`` (default: the file it came from)."""
        if self.avatar is None:
            raise InputError("nothing to save: this source is not an avatar")
        self.wait()
        target = Path(path) if path else self.path
        if target is None:
            raise InputError("save as: give a file name")
        if target.suffix.lower() != ".gma":
            raise InputError(f"{target}: an avatar file must end in .gma")
        if target.parent and not target.parent.is_dir():
            raise InputError(f"{target}: folder {target.parent} does not exist")
        try:
            self.avatar.save(target)
        except OSError as exc:
            raise InputError(f"cannot write {target}: {exc.strerror or exc}") from None
        self.source.path, self.source.name = target, target.name
        self.saved_mark = self._history_mark()
        self.state.message = f"saved {target} ({len(self.avatar.history)} history records)"
        return target


def merge_records(history: list[dict], start: int, params: dict) -> int:
    """Fold ``history[start:]`` (paint records of one stroke) into one record holding, for every face
    touched, its features from before the first dab: undoing it restores the stroke's start exactly.
    Returns the number of faces (0 when nothing was recorded)."""
    recs = history[start:]
    if not recs:
        return 0
    if len(recs) == 1:
        recs[0]["params"] = {**recs[0]["params"], **params}
        return int(recs[0].get("faces", 0))
    if any(r.get("op") != "paint" or "face_ids" not in r for r in recs):
        raise EditError("a stroke's history holds records other than paint")
    olds: dict[int, dict[str, torch.Tensor]] = {}
    for rec in reversed(recs):  # newest first, so the oldest value of each face wins
        ids, old = record_face_ids(rec), record_old(rec)
        for k, fid in enumerate(ids.tolist()):
            olds[fid] = {name: v[k] for name, v in old.items()}
    faces = torch.tensor(sorted(olds), dtype=torch.long)
    names = list(next(iter(olds.values())))
    old = {name: torch.stack([olds[f][name] for f in faces.tolist()]) for name in names}
    history[start:] = [make_record("paint", params, faces, old)]
    return len(faces)


def report(state, fn, *args, **kwargs):
    """Run a tool action; a user error (GmaError, OSError, ValueError) becomes the status message."""
    try:
        return fn(*args, **kwargs)
    except (GmaError, OSError, ValueError) as exc:
        state.message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return None
