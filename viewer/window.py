"""The glfw window: a wgpu surface (``wgpu.gpu.get_canvas_context`` with glfw's present info), mouse and
keyboard input mapped to :class:`ViewerState` actions, the frame loop, and screenshots of the surface.

Mouse: left drag orbits (navigate tool) or selects (box / lasso tool; Shift adds, Ctrl subtracts);
right or middle drag pans; wheel zooms. Keys: Space play/pause, R reset view, N/B/L navigate/box/lasso
tool, W wireframe, Esc clear selection, F1 panels on/off, 1-9 camera presets, 0 orbit camera.
"""

from __future__ import annotations

import time

import glfw
import numpy as np
import wgpu
from wgpu.utils.glfw_present_info import get_glfw_present_info

from gma.core.errors import DeviceError, GmaError
from gma.view.renderer import read_texture
from gma.view.timing import FrameStats
from viewer.state import ViewerState

__all__ = ["ViewerWindow"]


class ViewerWindow:
    """One viewer window on ``state``. ``panels``: draw the Dear ImGui panels (when imgui-bundle exists)."""

    def __init__(self, state: ViewerState, width: int = 800, height: int = 600, title: str = "GMA viewer",
                 panels: bool = True, vsync: bool = False, visible: bool = True):
        self.state, self.ctx = state, state.ctx
        self.ctx.check_image_size(int(width), int(height), "window")  # before glfw/wgpu, which abort on it
        if not glfw.init():
            raise DeviceError("cannot open a window: no display (set DISPLAY, or run under xvfb-run); "
                              "`gma render` makes videos without one")
        glfw.window_hint(glfw.CLIENT_API, glfw.NO_API)
        glfw.window_hint(glfw.VISIBLE, visible)
        self.window = glfw.create_window(int(width), int(height), title, None, None)
        if not self.window:
            raise DeviceError(f"glfw could not create a {width}x{height} window on this display")
        self.context = wgpu.gpu.get_canvas_context(get_glfw_present_info(self.window, vsync=vsync))
        caps = [str(f) for f in self.context._get_capabilities(self.ctx.adapter)["formats"]]
        # A non-sRGB target keeps the surfel image's bytes as they are (the offscreen render is rgba8unorm).
        self.format = next((f for f in ("bgra8unorm", "rgba8unorm") if f in caps),
                           self.context.get_preferred_format(self.ctx.adapter))
        self._configured_size = (0, 0)
        self.tool = "navigate"
        self.stats = FrameStats(self.ctx)
        self.ui = None
        if panels:
            try:
                from viewer.panels import Panels
            except ImportError as exc:  # imgui-bundle missing: keyboard/mouse only
                print(f"viewer: panels disabled ({exc}); install imgui-bundle for them")
            else:
                self.ui = Panels(self, self.format)
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

    def _on_button(self, window, button, action, mods) -> None:
        if self.ui is not None:
            self.ui.on_button(button, action)
        self._mods = mods
        x, y = self._to_pixels(*self._cursor)
        if action == glfw.PRESS and not self._ui_wants_mouse():
            kind = "pan" if button in (glfw.MOUSE_BUTTON_RIGHT, glfw.MOUSE_BUTTON_MIDDLE) else "orbit"
            if button == glfw.MOUSE_BUTTON_LEFT and mods & glfw.MOD_SHIFT and self.tool == "navigate":
                kind = "pan"
            if button == glfw.MOUSE_BUTTON_LEFT and self.tool in ("box", "lasso"):
                kind = self.tool
            self._drag = {"kind": kind, "start": (x, y), "last": (x, y), "points": [(x, y)], "mods": mods}
        elif action == glfw.RELEASE and self._drag is not None:
            self._finish_drag(x, y)

    def _finish_drag(self, x: float, y: float) -> None:
        d, self._drag = self._drag, None
        mode = "add" if d["mods"] & glfw.MOD_SHIFT else "subtract" if d["mods"] & glfw.MOD_CONTROL else "replace"
        try:
            if d["kind"] == "box":
                x0, y0 = d["start"]
                self.state.select_box((x0, y0, x, y), self.size, mode)
            elif d["kind"] == "lasso" and len(d["points"]) >= 3:
                self.state.select_lasso(d["points"], self.size, mode)
        except (GmaError, ValueError) as exc:
            self.state.message = str(exc)

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
        self._drag["last"] = (px, py)

    def _on_scroll(self, window, dx, dy) -> None:
        if self.ui is not None:
            self.ui.on_scroll(dx, dy)
        if not self._ui_wants_mouse():
            self.state.zoom_by(dy)

    def _on_char(self, window, codepoint) -> None:
        if self.ui is not None:
            self.ui.on_char(codepoint)

    def _on_key(self, window, key, scancode, action, mods) -> None:
        if self.ui is not None:
            self.ui.on_key(key, action, mods)
            if self.ui.visible and self.ui.wants_keyboard:
                return
        if action != glfw.PRESS:
            return
        s = self.state
        if key == glfw.KEY_SPACE and s.controls is not None:
            s.controls.playing = not s.controls.playing
        elif key == glfw.KEY_R:
            s.reset_view()
        elif key in (glfw.KEY_N, glfw.KEY_B, glfw.KEY_L):
            self.tool = {glfw.KEY_N: "navigate", glfw.KEY_B: "box", glfw.KEY_L: "lasso"}[key]
        elif key == glfw.KEY_W:
            s.scene.options.wireframe = not s.scene.options.wireframe
        elif key == glfw.KEY_ESCAPE:
            s.clear_selection()
        elif key == glfw.KEY_F1 and self.ui is not None:
            self.ui.visible = not self.ui.visible
        elif glfw.KEY_1 <= key <= glfw.KEY_9 and key - glfw.KEY_1 < len(s.presets):
            s.use_preset(key - glfw.KEY_1)
        elif key == glfw.KEY_0:
            s.use_preset(None)

    # -- frames -----------------------------------------------------------------------------------------
    def _drag_lines(self) -> list[np.ndarray] | None:
        d = self._drag
        if d is None or d["kind"] not in ("box", "lasso"):
            return None
        if d["kind"] == "box":
            (x0, y0), (x1, y1) = d["start"], d["last"]
            return [np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]], np.float32)]
        pts = np.asarray(d["points"] + [d["points"][0]], np.float32)
        return [pts]

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
        if (w, h) != self._configured_size:
            self.context.set_physical_size(w, h)
            self.context.configure(device=self.ctx.device, format=self.format,
                                   usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC,
                                   alpha_mode="opaque")
            self._configured_size = (w, h)
        texture = self.context.get_current_texture()
        view = texture.create_view()
        timer = self.stats.timer_for_frame()
        self.state.renderer.draw(self.state.scene, self.state.camera(w, h), view, self.format,
                                 lines=self._drag_lines(), timer=timer)
        if self.ui is not None and self.ui.visible:
            self.ui.draw(view, (w, h), dt)
        if self._want_capture:
            self._capture = read_texture(self.ctx, texture)
            self._want_capture = False
        self.context.present()
        self.stats.end_frame()

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
                self.draw_frame()
                if self.stats.frame % 60 == 0:
                    glfw.set_window_title(self.window, f"GMA viewer - {self.state.source.name} - "
                                                       f"{self.stats.summary()}")
        finally:
            self.close()

    def close(self) -> None:
        if self.window is not None:
            if self.state.recorder is not None:
                self.state.recorder.abort()
                self.state.recorder = None
            glfw.destroy_window(self.window)
            self.window = None
