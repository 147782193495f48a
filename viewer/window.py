"""The glfw window: a wgpu surface (``wgpu.gpu.get_canvas_context`` with glfw's present info), mouse and
keyboard input mapped to :class:`ViewerState` actions, the frame loop, and screenshots of the surface.

Every gesture is translated into a call on :class:`ViewerState` or its edit tools
(:class:`viewer.edit.EditTools`); the window itself holds no tool logic.

Mouse: left drag orbits (navigate), selects (box, lasso, brush; Shift adds, Ctrl subtracts), paints
(paint: strokes with the brush), picks (wand, eyedropper: click) or moves the stamp (stamp; Shift+drag
rotates, wheel scales); right or middle drag pans; wheel zooms. Files dropped on the window: images
become the stamp, .gma files the transfer donor.
Keys: Space play/pause, R reset view, N navigate, B box, L lasso, C brush select, M magic wand,
P paint, I eyedropper, T stamp, F fill selection, Enter apply stamp, G / Shift+G grow / shrink, U select
the faces the fit never saw (the highlight shows seen / guessed),
[ ] brush radius, X mirror left-right on/off, Ctrl+I invert, Esc clear selection, Ctrl+Z undo,
Ctrl+Shift+Z (or Ctrl+Y) redo, Ctrl+S save, W wireframe, F1 panels on/off, 1-9 camera presets, 0 orbit
camera. Closing with unsaved edits asks first (panels), or needs a second close (no panels).
"""

from __future__ import annotations

import time

import glfw
import numpy as np
import wgpu
from wgpu.utils.glfw_present_info import get_glfw_present_info

from gma.core.errors import DeviceError
from gma.view.quality import FULL, QualityGovernor
from gma.view.renderer import read_texture
from gma.view.timing import FrameStats
from viewer.actions import report
from viewer.state import ViewerState

__all__ = ["ViewerWindow"]

# The key choosing each tool.
_TOOL_KEYS = {glfw.KEY_N: "navigate", glfw.KEY_B: "box", glfw.KEY_L: "lasso", glfw.KEY_C: "brush",
              glfw.KEY_M: "wand", glfw.KEY_P: "paint", glfw.KEY_I: "eyedropper", glfw.KEY_T: "stamp"}


def _glfw_try(call, *args):
    """(call(*args), "") or, when glfw reports an error, (None, its reason: "X11: The DISPLAY environment
    variable is missing"). glfw reports errors as Python warnings by default, which would print two lines
    before the viewer's own one-line message; here they are raised and caught instead."""
    before, glfw.ERROR_REPORTING = glfw.ERROR_REPORTING, "raise"
    try:
        return call(*args), ""
    except glfw.GLFWError as exc:   # "(65550) b'X11: ...'": the code and the bytes quoting dropped
        text = str(exc)
        for quote in ("b'", 'b"'):
            if quote in text:
                text = text.split(quote, 1)[1].rstrip("'\"")
        return None, text
    finally:
        glfw.ERROR_REPORTING = before


class ViewerWindow:
    """One viewer window on ``state``. ``panels``: draw the Dear ImGui panels (when imgui-bundle exists).

    Frames while the view changes are drawn as cheaply as needed to keep ``target_fps``
    (:class:`gma.view.quality.QualityGovernor`; ``adaptive=False`` keeps full quality); once the view
    settles one full frame is drawn and then shown again, and the loop sleeps until the next event."""

    def __init__(self, state: ViewerState, width: int = 800, height: int = 600, title: str = "GMA viewer",
                 panels: bool = True, vsync: bool = False, visible: bool = True, target_fps: float = 12.0,
                 adaptive: bool = True):
        self.state, self.ctx = state, state.ctx
        self.ctx.check_image_size(int(width), int(height), "window")  # before glfw/wgpu, which abort on it
        ok, why = _glfw_try(glfw.init)
        if not ok:
            raise DeviceError(f"cannot open a window: no display{f' ({why})' if why else ''}; set DISPLAY, or "
                              "run under xvfb-run (`gma render` makes videos without one)")
        glfw.window_hint(glfw.CLIENT_API, glfw.NO_API)
        glfw.window_hint(glfw.VISIBLE, visible)
        self.title = title
        self.window, why = _glfw_try(glfw.create_window, int(width), int(height), title, None, None)
        if not self.window:
            raise DeviceError(f"glfw could not create a {width}x{height} window on this display"
                              f"{f': {why}' if why else ''}")
        self.context = wgpu.gpu.get_canvas_context(get_glfw_present_info(self.window, vsync=vsync))
        caps = [str(f) for f in self.context._get_capabilities(self.ctx.adapter)["formats"]]
        # A non-sRGB target keeps the surfel image's bytes as they are (the offscreen render is rgba8unorm).
        self.format = next((f for f in ("bgra8unorm", "rgba8unorm") if f in caps),
                           self.context.get_preferred_format(self.ctx.adapter))
        self._configured_size = (0, 0)
        self.tool = "navigate"
        self.stats = FrameStats(self.ctx)
        self.quality = QualityGovernor(target_fps, adaptive)
        self._view_key = None
        self.last_quality = FULL  # what the last frame drew (None: it showed the previous full frame again)
        self.ui = None
        if panels:
            try:  # imported here because imgui-bundle is optional
                from viewer.panels import Panels
            except ImportError as exc:  # imgui-bundle missing: keyboard/mouse only
                print(f"viewer: panels disabled ({exc}); install imgui-bundle for them")
            else:
                self.ui = Panels(self, self.format)
        if state.edit is not None:
            state.edit.background = True  # solves run beside the frame loop (see viewer.edit)
        self._drag: dict | None = None
        self._mods = 0
        self._cursor = (0.0, 0.0)  # last cursor position in window coordinates (from the callback)
        self._last_time = time.perf_counter()
        self._capture: np.ndarray | None = None
        self._want_capture = False
        w = self.window
        glfw.set_mouse_button_callback(w, self._on_button)
        glfw.set_cursor_pos_callback(w, self._on_cursor)
        glfw.set_scroll_callback(w, self._on_scroll)
        glfw.set_key_callback(w, self._on_key)
        glfw.set_char_callback(w, self._on_char)
        glfw.set_drop_callback(w, self._on_drop)
        glfw.set_window_close_callback(w, self._on_close_request)
        self.confirm_close = False  # an unsaved-edits question is open (the panels show it)
        self._close_asked = False
        self._shown_title = ""
        self._stats_text = ""
        self.update_title()

    # -- geometry ---------------------------------------------------------------------------------------
    @property
    def size(self) -> tuple[int, int]:
        """Framebuffer size in pixels (what is rendered)."""
        w, h = glfw.get_framebuffer_size(self.window)
        return max(int(w), 1), max(int(h), 1)

    def _to_pixels(self, x: float, y: float) -> tuple[float, float]:
        ww, wh = glfw.get_window_size(self.window)
        fw, fh = self.size
        return x * fw / max(ww, 1), y * fh / max(wh, 1)

    # -- input ------------------------------------------------------------------------------------------
    def _ui_wants_mouse(self) -> bool:
        return self.ui is not None and self.ui.visible and self.ui.wants_mouse

    @property
    def edit(self):
        return self.state.edit

    def _mode(self, mods: int) -> str:
        return "add" if mods & glfw.MOD_SHIFT else "subtract" if mods & glfw.MOD_CONTROL else "replace"

    def _on_button(self, window, button, action, mods) -> None:
        if self.ui is not None:
            self.ui.on_button(button, action)
        self._mods = mods
        x, y = self._to_pixels(*self._cursor)
        if action == glfw.PRESS and not self._ui_wants_mouse():
            kind = "pan" if button in (glfw.MOUSE_BUTTON_RIGHT, glfw.MOUSE_BUTTON_MIDDLE) else "orbit"
            if button == glfw.MOUSE_BUTTON_LEFT:
                if mods & glfw.MOD_SHIFT and self.tool == "navigate":
                    kind = "pan"
                elif self.tool != "navigate" and self.edit is not None:
                    kind = self.tool
            self._drag = {"kind": kind, "start": (x, y), "last": (x, y), "points": [(x, y)], "mods": mods}
            if kind in ("brush", "paint"):
                mode = "paint" if kind == "paint" else "deselect" if mods & glfw.MOD_CONTROL else "select"
                if kind == "brush" and self._mode(mods) == "replace":
                    report(self.state, self.edit.clear)
                if report(self.state, self.edit.stroke_begin, x, y, mode) is None and self.edit.stroke is None:
                    self._drag = None
        elif action == glfw.RELEASE and self._drag is not None:
            self._finish_drag(x, y)

    def _finish_drag(self, x: float, y: float) -> None:
        d, self._drag = self._drag, None
        mode, kind, ed = self._mode(d["mods"]), d["kind"], self.edit
        if kind == "box":
            x0, y0 = d["start"]
            report(self.state, ed.select_box, (x0, y0, x, y), self.size, mode)
        elif kind == "lasso" and len(d["points"]) >= 3:
            report(self.state, ed.select_lasso, d["points"], self.size, mode)
        elif kind in ("brush", "paint"):
            report(self.state, ed.stroke_end, self.size)
        elif kind == "wand":
            report(self.state, ed.select_wand, x, y, self.size, mode)
        elif kind == "eyedropper":
            report(self.state, ed.pick_color, x, y, self.size)

    def _on_cursor(self, window, x, y) -> None:
        if self.ui is not None:
            self.ui.on_cursor(x, y)
        self._cursor = (x, y)
        if self._drag is None:
            return
        px, py = self._to_pixels(x, y)
        lx, ly = self._drag["last"]
        dx, dy = px - lx, py - ly
        kind = self._drag["kind"]
        if kind == "orbit":
            self.state.orbit_by(dx, dy)
        elif kind == "pan":
            self.state.pan_by(dx, dy, self.size[1])
        elif kind == "lasso":
            self._drag["points"].append((px, py))
        elif kind in ("brush", "paint"):
            self.edit.stroke_to(px, py)  # applied once per frame, in draw_frame
        elif kind == "stamp":
            if self._drag["mods"] & glfw.MOD_SHIFT:
                report(self.state, self.edit.rotate_stamp, -dx * 0.5)
            else:
                report(self.state, self.edit.move_stamp, dx, dy, self.size)
        self._drag["last"] = (px, py)

    def _on_drop(self, window, paths) -> None:
        """Files dropped on the window: an avatar becomes the transfer donor, an image the stamp."""
        if self.edit is None:
            self.state.message = "this source cannot be edited"
            return
        for p in paths:
            if str(p).lower().endswith(".gma"):
                report(self.state, self.edit.load_donor, p)
            elif report(self.state, self.edit.load_stamp, p) is not None:
                self.tool = "stamp"
                if self.ui is not None:
                    self.ui.stamp_path = str(p)

    def _on_scroll(self, window, dx, dy) -> None:
        if self.ui is not None:
            self.ui.on_scroll(dx, dy)
        if self._ui_wants_mouse():
            return
        if self.tool == "stamp" and self.edit is not None and self.edit.stamp is not None:
            self.edit.scale_stamp(1.1 ** dy)
        else:
            self.state.zoom_by(dy)

    def _on_char(self, window, codepoint) -> None:
        if self.ui is not None:
            self.ui.on_char(codepoint)

    def _on_key(self, window, key, scancode, action, mods) -> None:
        if self.ui is not None:
            self.ui.on_key(key, action, mods)
            if self.ui.visible and self.ui.wants_keyboard:
                return
        if action not in (glfw.PRESS, glfw.REPEAT):
            return
        s, ed = self.state, self.edit
        ctrl, shift = bool(mods & glfw.MOD_CONTROL), bool(mods & glfw.MOD_SHIFT)
        if ctrl and ed is not None:
            if key == glfw.KEY_Z and shift or key == glfw.KEY_Y:
                report(s, ed.redo)
            elif key == glfw.KEY_Z:
                report(s, ed.undo)
            elif key == glfw.KEY_S:
                report(s, ed.save)
            elif key == glfw.KEY_I:
                report(s, ed.invert)
            return
        if key == glfw.KEY_LEFT_BRACKET and ed is not None:
            ed.brush.radius = max(2.0, ed.brush.radius / 1.2)
        elif key == glfw.KEY_RIGHT_BRACKET and ed is not None:
            ed.brush.radius = min(500.0, ed.brush.radius * 1.2)
        if action != glfw.PRESS:
            return
        if key == glfw.KEY_SPACE and s.controls is not None:
            s.controls.playing = not s.controls.playing
        elif key == glfw.KEY_R:
            s.reset_view()
        elif key in _TOOL_KEYS and (ed is not None or _TOOL_KEYS[key] == "navigate"):
            self.tool = _TOOL_KEYS[key]
        elif key == glfw.KEY_F and ed is not None:
            report(s, ed.fill)
        elif key in (glfw.KEY_ENTER, glfw.KEY_KP_ENTER) and ed is not None and self.tool == "stamp":
            report(s, ed.apply_stamp, self.size)
        elif key == glfw.KEY_U and ed is not None:
            report(s, ed.select_unseen)
        elif key == glfw.KEY_G and ed is not None:
            report(s, ed.shrink if shift else ed.grow)
        elif key == glfw.KEY_W:
            s.scene.options.wireframe = not s.scene.options.wireframe
        elif key == glfw.KEY_X and ed is not None:
            ed.mirror = not ed.mirror
            s.message = f"mirror left-right {'on' if ed.mirror else 'off'}"
        elif key == glfw.KEY_ESCAPE and ed is not None:
            report(s, ed.clear)
        elif key == glfw.KEY_F1 and self.ui is not None:
            self.ui.visible = not self.ui.visible
        elif glfw.KEY_1 <= key <= glfw.KEY_9 and key - glfw.KEY_1 < len(s.presets):
            s.use_preset(key - glfw.KEY_1)
        elif key == glfw.KEY_0:
            s.use_preset(None)

    # -- closing and the title ------------------------------------------------------------------------
    @property
    def dirty(self) -> bool:
        return self.edit is not None and self.edit.dirty

    def _on_close_request(self, window) -> None:
        """Closing with unsaved edits: keep the window open and ask (panels), or warn once (no panels)."""
        if self.dirty and not self._close_asked:
            glfw.set_window_should_close(window, False)
            self._close_asked = True
            self.confirm_close = self.ui is not None
            self.state.message = "unsaved edits: Ctrl+S saves; close again to discard them"

    def discard_and_close(self) -> None:
        self._close_asked, self.confirm_close = True, False
        glfw.set_window_should_close(self.window, True)

    def cancel_close(self) -> None:
        self._close_asked = self.confirm_close = False
        self.state.message = ""

    def update_title(self, stats: str = "") -> None:
        """``GMA viewer - name* - stats``: the star marks unsaved edits."""
        name = self.state.source.name + ("*" if self.dirty else "")
        title = f"{self.title} - {name}" + (f" - {stats}" if stats else "")
        if title != self._shown_title:
            glfw.set_window_title(self.window, title)
            self._shown_title = title

    # -- frames -----------------------------------------------------------------------------------------
    def _overlays(self) -> tuple[list[np.ndarray], list]:
        """Lines and images over the frame: the drag outline and the edit tools' overlays."""
        lines = self._drag_lines() or []
        images = []
        if self.edit is not None:
            more, images = self.edit.overlays(self.size, self.tool, self._to_pixels(*self._cursor))
            lines += more
        return lines, images

    def _drag_lines(self) -> list[np.ndarray] | None:
        d = self._drag
        if d is None or d["kind"] not in ("box", "lasso"):
            return None
        if d["kind"] == "box":
            (x0, y0), (x1, y1) = d["start"], d["last"]
            return [np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], np.float32)]
        pts = np.asarray(d["points"] + [d["points"][0]], np.float32)
        return [pts]

    @property
    def idle(self) -> bool:
        """The last frame showed the settled view again and nothing runs in the background: the loop can
        wait for input instead of drawing."""
        busy = self.edit is not None and (self.edit.busy or self.edit.stroke is not None)
        return self.last_quality is None and not busy and self.state.recorder is None and self._drag is None

    def draw_frame(self) -> None:
        """Poll input, advance playback (or recording), draw and present one frame."""
        glfw.poll_events()
        now = time.perf_counter()
        dt, self._last_time = now - self._last_time, now
        if self.state.recorder is not None:
            self.state.record_step()
        else:
            self.state.tick(dt)
        w, h = self.size
        if self.edit is not None:
            report(self.state, self.edit.poll, False)  # a background edit that finished: upload its rows
            if self.edit.stroke is not None:
                report(self.state, self.edit.stroke_update, (w, h))  # the dabs queued since the last frame
        if (w, h) != self._configured_size:
            self.context.set_physical_size(w, h)
            self.context.configure(device=self.ctx.device, format=self.format,
                                   usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC,
                                   alpha_mode="opaque")
            self._configured_size = (w, h)
        camera = self.state.camera(w, h)
        key = self.state.renderer.view_key(self.state.scene, camera)
        changed, self._view_key = key != self._view_key, key
        if self.state.recorder is not None or self._want_capture:
            changed = False  # a capture shows the full frame (the renderer redraws it if the view changed)
        quality = self.quality.next_frame(changed)
        texture = self.context.get_current_texture()
        view = texture.create_view()
        timer = self.stats.timer_for_frame()
        lines, images = self._overlays()
        self.state.renderer.draw(self.state.scene, camera, view, self.format, lines=lines, timer=timer,
                                 images=images, quality=quality)
        self.last_quality = quality
        if self.ui is not None and self.ui.visible:
            self.ui.draw(view, (w, h), dt)
        if self._want_capture:
            self._capture = read_texture(self.ctx, texture)
            self._want_capture = False
        self.context.present()
        self.quality.frame_done((time.perf_counter() - now) * 1e3)
        self.stats.end_frame()
        self.update_title(self._stats_text)  # sets the title only when it changes (the dirty marker)
        if self.edit is not None:
            self.edit.start()  # a solve queued this frame starts now that its preview is on screen

    def screenshot(self) -> np.ndarray:
        """Draw a frame and return what was presented: [H, W, 4] uint8 RGBA."""
        self._want_capture = True
        self.draw_frame()
        return self._capture

    @property
    def should_close(self) -> bool:
        return bool(glfw.window_should_close(self.window))

    def run(self) -> None:
        """The frame loop, until the window is closed."""
        try:
            while not self.should_close:
                if self.last_quality is None:
                    # Nothing to redraw: sleep until input arrives, so that a still window leaves the cores
                    # to the edit solves and other work (a running solve or stroke is polled 100 times a
                    # second, an idle window 20 times).
                    glfw.wait_events_timeout(0.05 if self.idle else 0.01)
                self.draw_frame()
                if self.stats.frame % 60 == 0:
                    self._stats_text = f"{self.stats.summary()} | {self.quality.quality.label()}"
        finally:
            self.close()

    def close(self) -> None:
        if self.window is not None:
            if self.state.recorder is not None:
                self.state.recorder.abort()
                self.state.recorder = None
            glfw.destroy_window(self.window)
            self.window = None
