"""The stamp tool: an image placed over the current view (moved, scaled, rotated) and stamped onto the
visible surfels it covers."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.errors import InputError
from gma.edit import StampPlacement, load_stamp_image

__all__ = ["StampState", "StampTools"]


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


class StampTools:
    """The stamp part of :class:`viewer.edit.EditTools`."""

    def _init_stamp(self) -> None:
        self.stamp: StampState | None = None
        self.stamp_in_selection = False  # restrict the stamp to the selection

    def _replace_stamp_image(self, image: np.ndarray, name: str) -> StampState:
        """A new image keeps the placement of the previous one."""
        old = self.stamp
        self.stamp = StampState(image, name)
        if old is not None:
            self.stamp.centre, self.stamp.size, self.stamp.rotation = old.centre, old.size, old.rotation
            self.stamp.version = old.version + 1
        return self.stamp

    def load_stamp(self, path) -> StampState:
        """Load an image (PNG with alpha, JPEG, ...) to place; keeps the placement of a previous one."""
        img = load_stamp_image(path)
        self._replace_stamp_image(img, Path(path).name)
        self.state.message = f"stamp {Path(path).name}: {img.shape[1]}x{img.shape[0]}; drag to move, " \
                             "wheel to scale, Shift+drag to rotate, Enter to apply"
        return self.stamp

    def set_stamp_image(self, image: np.ndarray, name: str = "image") -> StampState:
        """Place an RGBA [h, w, 4] float image (e.g. :func:`gma.edit.solid_shape`)."""
        return self._replace_stamp_image(np.asarray(image, np.float32), name)

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
