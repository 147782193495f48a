"""Paint tools: the colour (picker, hex, eyedropper), fill the selection, and brush strokes that paint
or select while dragging. A stroke's dabs are queued as the cursor moves and applied once per frame; in
the background they show as a preview at once and are solved together when the worker is free, and the
finished stroke is folded into one history record (one undo takes it back)."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from gma.core.errors import InputError
from gma.edit import Selection, parse_color
from viewer.edit.history import merge_records

__all__ = ["BrushSettings", "PaintTools", "StrokeStats"]


@dataclass
class BrushSettings:
    """Circular brush: ``radius`` in pixels, ``falloff`` the soft fraction of the radius (0: hard edge)."""

    radius: float = 20.0
    falloff: float = 0.5


@dataclass
class StrokeStats:
    """Timings of the current / last brush stroke (for the panel and the benchmark)."""

    dabs: int = 0
    updates: int = 0
    faces: int = 0
    update_ms: list[float] = field(default_factory=list)


class PaintTools:
    """The paint part of :class:`viewer.edit.EditTools`."""

    def _init_paint(self) -> None:
        self.brush = BrushSettings()
        self.color = (0.75, 0.19, 0.19)
        self.stroke: StrokeStats | None = None  # the stroke being drawn
        self.last_stroke = StrokeStats()
        self._pending: list[tuple[float, float]] = []  # cursor positions since the last update
        self._last_dab: tuple[float, float] | None = None
        self._stroke_start = 0  # history length when the stroke began
        self._stroke_mode = "paint"
        self._stroke_size = (1, 1)
        self._stroke_color = self.color
        self._stroke_todo: Selection | None = None  # dabs shown as preview, not solved yet
        self._ending = False  # released: solve what is left, then fold the stroke into one record

    # -- colour and fill --------------------------------------------------------------------------------
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
        self._stroke_todo = None
        self._ending = False
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

    def _dabs_selection(self, size) -> Selection | None:
        """The union of the brush discs of the dabs queued since the last update (weights by maximum),
        or None when there are none."""
        pts = self._dab_points()
        if not pts:
            return None
        view, sel = self.view(size), None
        for p in pts:
            disc = Selection.brush(view, p, self.brush.radius, self.brush.falloff)
            sel = disc if sel is None else sel.union(disc)
        self.stroke.dabs += len(pts)
        return sel

    def stroke_update(self, size) -> bool:
        """Apply the dabs queued since the last call. Called once per frame while dragging; True when the
        frame changed. In the background the dabs are shown as a preview at once and solved together when
        the previous solve is done."""
        if self.stroke is None:
            return False
        self._stroke_size = size
        landed = self._stroke_mode == "paint" and self.busy and self.poll(start=False) is not None
        if landed and self._stroke_todo is not None:
            # the landed solve rewrote rows that newer, unsolved dabs also cover: show those again
            self._preview(self._stroke_todo, self._stroke_color)
        t0 = time.perf_counter()
        sel = self._dabs_selection(size)
        if self._stroke_mode != "paint":
            return self._select_stroke_update(sel)
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
        self._solve_stroke_todo()
        self.stroke.update_ms.append((time.perf_counter() - t0) * 1e3)
        return True

    def _select_stroke_update(self, sel: Selection | None) -> bool:
        """A selecting stroke: add (or remove) the dabs at once; set_selection adds the mirror image."""
        if sel is not None:
            self.set_selection(sel, "add" if self._stroke_mode == "select" else "subtract")
        if self._ending:
            self.last_stroke, self.stroke = self.stroke, None
        return sel is not None

    def _solve_stroke_todo(self) -> None:
        """Paint the dabs not solved yet (one solve for all of them); the last one also merges the stroke."""
        todo, self._stroke_todo = self._stroke_todo, None
        self.stroke.faces += len(todo)
        self.stroke.updates += 1
        editor, color = self.editor, self._stroke_color
        self._run("paint", lambda: editor.paint(todo, color), after=self._merge_stroke if self._ending else None)

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
