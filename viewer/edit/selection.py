"""Selection tools: box, lasso, brush, magic wand, body regions, grow / shrink, invert, clear, and the
left-right mirror. Selections are made in the :class:`gma.edit.ScreenView` of what is on screen now, so
only faces visible in the current view are hit."""

from __future__ import annotations

import numpy as np
import torch

from gma.core.errors import InputError
from gma.edit import EditError, Selection, mirror_map

__all__ = ["SelectionTools"]


class SelectionTools:
    """The selection part of :class:`viewer.edit.EditTools` (which provides ``view``, ``editor`` and the
    rest of the session)."""

    def _init_selection(self) -> None:
        self.selection = Selection(torch.zeros(0, dtype=torch.long), self.body.num_faces)
        self.wand_tolerance = 0.1
        self.mirror = False  # selections and paint strokes also take their mirror image (left-right)
        self._mirror_map: torch.Tensor | None = None
        self._face_graph = None  # face adjacency for grow / shrink before any edit made an editor

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
        if self._face_graph is None:
            from gma.edit import FaceGraph

            self._face_graph = FaceGraph(self.body.faces)
        return self._face_graph
