"""The base of the viewer's edit tools: the viewer state and source they act on, the editing session
(:class:`gma.edit.Editor`), the cached view of what is on screen, and how an edit runs and lands: on this
thread, or on the worker with a preview of its colours shown at once."""

from __future__ import annotations

import time

import numpy as np
import torch

from gma.core.errors import InputError
from gma.edit import Editor, ScreenView, Selection
from viewer.edit.worker import EditJob, EditWorker

__all__ = ["EditSession"]


class EditSession:
    """State shared by every tool, on a viewer ``state`` (:class:`viewer.state.ViewerState`) whose source
    is bound to a body. ``background``: edits run on the worker thread (the window's setting)."""

    def __init__(self, state, background: bool = False):
        self.state = state
        self.background = background
        self._worker = EditWorker()
        self.source = state.source
        self.body = self.source.body
        self.version = 0  # edits applied (including undo / redo)
        self.last_change_ms = 0.0
        self._editor: Editor | None = None
        self._view: ScreenView | None = None
        self._view_key = None
        self._ids = None  # the face-ID renderer, made on the first view
        self._previewed: torch.Tensor | None = None  # GPU colour rows showing a preview now

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

    def view(self, size: tuple[int, int]) -> ScreenView:
        """What is on screen now for a ``size`` = (w, h) frame: camera, posed mesh and face-ID render
        (cached until the camera, the size or the pose changes, so a brush stroke renders IDs once)."""
        cam = self.state.camera(*size)
        key = (cam.viewmat.tobytes(), cam.K.tobytes(), cam.width, cam.height, self.source.pose_version)
        if key != self._view_key:
            if self._ids is None:
                from gma.render.face_id import FaceIdRenderer

                self._ids = FaceIdRenderer(self.state.ctx, self.body.faces.numpy())
            self._view = ScreenView.render(self._ids, self.source.posed_vertices(), self.body.faces.numpy(), cam)
            self._view_key = key
        return self._view

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

    def keep_body(self):
        """Write the Body panel's shape and expression into the avatar (undoable, saved with it)."""
        self.wait()
        ctl, editor = self.state.controls, self.editor
        # Checked here, on this thread, so a value out of the body's range is refused at once.
        shape, expr = editor.check_body(ctl.shape.clone(), ctl.expression.clone())
        return self._run("body", lambda: editor.set_body(shape=shape, expression=expr))

    def _run(self, what: str, fn, preview: tuple | None = None, after=None):
        """Run one edit ``fn`` (returning a Change or a list), apply it, time it and report it in the
        status line; ``preview`` (selection, colour) is shown at once; ``after`` runs (on this thread)
        once the change is applied. In the background: returns None at once, see :meth:`poll`."""
        self._join()
        job = EditJob(what, fn, after)
        if preview is not None:
            self._preview(*preview)
        if not self.background:
            job.change = fn()  # a user error propagates to the caller here
            return self._finish(job)
        self._worker.submit(job)
        self.state.message = f"{what}..."
        return None

    def _now(self, what: str, fn):
        """Run ``fn`` on this thread and apply its change (undo / redo restore stored rows: no solve)."""
        job = EditJob(what, fn)
        job.change = fn()
        return self._finish(job)

    def _finish(self, job: EditJob):
        change = job.change
        self.apply(change)
        self.last_change_ms = (time.perf_counter() - job.t0) * 1e3
        n = sum(len(c.faces) for c in change) if isinstance(change, list) else len(change.faces)
        self.state.message = f"{job.what}: {n} faces in {self.last_change_ms:.0f} ms"
        if job.after is not None:
            job.after()
        return change

    # -- the background edit ----------------------------------------------------------------------------
    @property
    def busy(self) -> bool:
        """An edit is running on the worker thread."""
        return self._worker.busy

    def start(self) -> None:
        """Start the queued background solve. The window calls this after presenting a frame, so the
        frame showing an edit's preview is drawn before the solve competes with it for the CPU."""
        self._worker.start()

    def poll(self, start: bool = True):
        """Apply the background edit if it has finished (call once per frame). Returns its change, or
        None; a failed edit raises its error here (and its preview is taken back)."""
        job = self._worker.take_finished(start)
        return None if job is None else self._land(job)

    def _join(self):
        """Wait for the running background edit, if any, and apply it."""
        job = self._worker.join()
        return None if job is None else self._land(job)

    def _land(self, job: EditJob):
        if job.error is not None:
            self._unpreview()
            raise job.error
        return self._finish(job)

    def wait(self) -> None:
        """Wait until the edit asked for has landed."""
        self._join()

    # -- preview ----------------------------------------------------------------------------------------
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
        rows = self._previewed
        if rows is not None:
            self.source.write_colors(rows.numpy(), self.source.decoded.colors[rows].numpy())
            self._previewed = None
