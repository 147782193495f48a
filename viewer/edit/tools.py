""":class:`EditTools`: every edit tool of the viewer on one object, composed from the tool modules of
this package (selection, paint, stamp, transfer, history) over the shared session."""

from __future__ import annotations

import numpy as np

from viewer.edit.history import HistoryTools
from viewer.edit.paint import PaintTools
from viewer.edit.selection import SelectionTools
from viewer.edit.session import EditSession
from viewer.edit.stamp import StampTools
from viewer.edit.transfer import TransferTools

__all__ = ["EditTools"]


class EditTools(SelectionTools, PaintTools, StampTools, TransferTools, HistoryTools, EditSession):
    """Edit tools on a viewer ``state`` (:class:`viewer.state.ViewerState`) whose source is bound to a
    body. Editing features needs an avatar source (``source.avatar``); selection works on any body."""

    def __init__(self, state, background: bool = False):
        EditSession.__init__(self, state, background)
        self._init_selection()
        self._init_paint()
        self._init_stamp()
        self._init_transfer()
        self._init_history()

    def wait(self) -> None:
        """Wait until every edit asked for has landed (the running one, and the rest of a finished
        brush stroke)."""
        while True:
            if self.busy:
                self._join()
            elif self.stroke is not None and self._ending:
                self.stroke_update(self._stroke_size)  # submits the stroke's last dabs, or merges it
            else:
                return

    def overlays(self, size, tool: str, cursor=None) -> tuple[list[np.ndarray], list]:
        """(lines, images) to draw over the frame for ``tool`` with the cursor at ``cursor`` (pixels): the
        brush circle, the stamp preview quad, the donor thumbnail. Pure geometry: no GPU work here."""
        lines, images = [], []
        if tool in ("brush", "paint") and cursor is not None:
            lines += self._brush_circles(cursor)
        if tool == "stamp" and self.stamp is not None:
            self._add_quad(lines, images, self.stamp.corners(*size), self.stamp.image, "stamp", 0.75)
        if self.donor_thumbnail is not None:
            self._add_quad(lines, images, self._thumbnail_corners(size), self.donor_thumbnail, "donor")
        return lines, images

    def _brush_circles(self, cursor) -> list[np.ndarray]:
        """The brush's outline, and the inner circle where its falloff begins."""
        a = np.linspace(0, 2 * np.pi, 33)
        radii = [self.brush.radius]
        if self.brush.falloff > 0:
            radii.append(self.brush.radius * (1 - self.brush.falloff))
        return [np.c_[cursor[0] + r * np.cos(a), cursor[1] + r * np.sin(a)].astype(np.float32) for r in radii]

    def _thumbnail_corners(self, size) -> np.ndarray:
        """[4, 2] pixel corners of the donor thumbnail in the bottom-right corner (at most 30 % of the
        frame's height)."""
        w, h = size
        th, tw = self.donor_thumbnail.shape[:2]
        s = min(1.0, 0.3 * h / th)
        x0, y0 = w - tw * s - 4, h - th * s - 4
        return np.array([[x0, y0], [x0 + tw * s, y0], [x0 + tw * s, y0 + th * s], [x0, y0 + th * s]], np.float32)

    @staticmethod
    def _add_quad(lines: list, images: list, corners: np.ndarray, image: np.ndarray, kind: str,
                  opacity: float = 1.0) -> None:
        """An image drawn on the quad ``corners`` (cached by the renderer per ``kind`` and image), outlined."""
        from gma.view import ScreenImage

        images.append(ScreenImage(image, corners, (kind, id(image)), opacity))
        lines.append(np.r_[corners, corners[:1]])
