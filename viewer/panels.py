"""Dear ImGui panels (imgui-bundle, drawn with wgpu-py's ``ImguiWgpuBackend``): Render, Record, Body,
Edit, and the FPS / per-pass GPU time overlay. Every widget calls a :class:`ViewerState` action, so what
a panel does can also be done (and tested) without it. Input arrives from the window's glfw callbacks.
"""

from __future__ import annotations

import glfw
import wgpu
from imgui_bundle import imgui
from wgpu.utils.imgui.imgui_backend import ImguiWgpuBackend

from gma.body.motions import MOTIONS
from gma.core.errors import GmaError

__all__ = ["Panels"]

_KEYS = {glfw.KEY_BACKSPACE: imgui.Key.backspace, glfw.KEY_DELETE: imgui.Key.delete, glfw.KEY_ENTER: imgui.Key.enter,
         glfw.KEY_LEFT: imgui.Key.left_arrow, glfw.KEY_RIGHT: imgui.Key.right_arrow, glfw.KEY_HOME: imgui.Key.home,
         glfw.KEY_END: imgui.Key.end, glfw.KEY_TAB: imgui.Key.tab, glfw.KEY_ESCAPE: imgui.Key.escape,
         glfw.KEY_UP: imgui.Key.up_arrow, glfw.KEY_DOWN: imgui.Key.down_arrow}
_TOOLS = ("navigate", "box", "lasso")


class Panels:
    """The viewer's panels for one window (``window``: a :class:`viewer.window.ViewerWindow`)."""

    def __init__(self, window, target_format: str):
        self.window, self.state = window, window.state
        self.visible = True
        self.context = imgui.create_context()
        imgui.set_current_context(self.context)
        self.backend = ImguiWgpuBackend(window.ctx.device, target_format)
        self.io = self.backend.io
        self.selection_path = "selection.json"
        self.motion_path = ""
        self._motion_index = 0

    # -- input from glfw --------------------------------------------------------------------------------
    @property
    def wants_mouse(self) -> bool:
        return bool(self.io.want_capture_mouse)

    @property
    def wants_keyboard(self) -> bool:
        return bool(self.io.want_capture_keyboard)

    def on_cursor(self, x: float, y: float) -> None:
        self.io.add_mouse_pos_event(x, y)

    def on_button(self, button: int, action: int) -> None:
        if button < 3:
            self.io.add_mouse_button_event(button, action == glfw.PRESS)

    def on_scroll(self, dx: float, dy: float) -> None:
        self.io.add_mouse_wheel_event(dx, dy)

    def on_char(self, codepoint: int) -> None:
        self.io.add_input_character(codepoint)

    def on_key(self, key: int, action: int, mods: int) -> None:
        if key in _KEYS and action in (glfw.PRESS, glfw.RELEASE):
            self.io.add_key_event(_KEYS[key], action == glfw.PRESS)

    # -- frame ----------------------------------------------------------------------------------------
    def draw(self, view: wgpu.GPUTextureView, size: tuple[int, int], dt: float) -> None:
        imgui.set_current_context(self.context)
        ww, wh = glfw.get_window_size(self.window.window)
        self.io.display_size = (ww, wh)
        self.io.display_framebuffer_scale = (size[0] / max(ww, 1), size[1] / max(wh, 1))
        self.io.delta_time = max(dt, 1e-4)
        imgui.new_frame()
        try:
            self._stats()
            self._main_panel()
        finally:
            imgui.render()
        enc = self.window.ctx.device.create_command_encoder(label="viewer.imgui")
        rp = enc.begin_render_pass(color_attachments=[{"view": view, "load_op": wgpu.LoadOp.load,
                                                       "store_op": wgpu.StoreOp.store}])
        self.backend.render(imgui.get_draw_data(), rp)
        rp.end()
        self.window.ctx.device.queue.submit([enc.finish()])

    def _stats(self) -> None:
        ww = glfw.get_window_size(self.window.window)[0]
        imgui.set_next_window_pos(imgui.ImVec2(ww - 10, 10), 0, imgui.ImVec2(1, 0))
        flags = (imgui.WindowFlags_.no_decoration | imgui.WindowFlags_.always_auto_resize
                 | imgui.WindowFlags_.no_inputs)
        imgui.set_next_window_bg_alpha(0.6)
        imgui.begin("stats", None, flags)
        st = self.window.stats
        imgui.text(f"{st.fps:.1f} FPS  {st.frame_ms:.1f} ms")
        for name, ms in st.gpu_ms.items():
            imgui.text(f"{name:>10s} {ms:6.2f} ms")
        if not st.gpu_ms:
            imgui.text("(no GPU timestamps)" if not self.window.ctx.has_timestamps else "")
        imgui.end()

    def _main_panel(self) -> None:
        imgui.set_next_window_pos(imgui.ImVec2(10, 10), imgui.Cond_.once)
        imgui.begin("GMA", None, imgui.WindowFlags_.always_auto_resize)
        if imgui.collapsing_header("Render", imgui.TreeNodeFlags_.default_open):
            self._render_panel()
        if self.state.controls is not None and imgui.collapsing_header("Body"):
            self._body_panel()
        if imgui.collapsing_header("Record"):
            self._record_panel()
        if self.state.controls is not None and imgui.collapsing_header("Edit"):
            self._edit_panel()
        if self.state.message:
            imgui.text_wrapped(self.state.message)
        imgui.end()

    def _render_panel(self) -> None:
        s, opts = self.state, self.state.scene.options
        if imgui.button("reset view"):
            s.reset_view()
        if s.presets:
            names = ["orbit"] + [f"camera {i}" for i in range(len(s.presets))]
            changed, i = imgui.combo("camera", 0 if s.preset is None else s.preset + 1, names)
            if changed:
                s.use_preset(None if i == 0 else i - 1)
        ctl = s.controls
        if ctl is not None:
            items = ["canonical"] + list(MOTIONS)
            changed, self._motion_index = imgui.combo("motion", self._motion_index, items)
            if changed:
                s.play_motion(None if self._motion_index == 0 else items[self._motion_index])
            _, self.motion_path = imgui.input_text("motion file", self.motion_path)
            imgui.same_line()
            if imgui.button("load##motion") and self.motion_path:
                try:
                    s.play_motion(self.motion_path)
                except (GmaError, OSError, ValueError) as exc:
                    s.message = str(exc)
            if ctl.motion is not None:
                if imgui.button("pause" if ctl.playing else "play"):
                    ctl.playing = not ctl.playing
                imgui.same_line()
                changed, f = imgui.slider_int("frame", ctl.frame, 0, ctl.num_frames - 1)
                if changed:
                    ctl.playing = False
                    ctl.scrub(f)
        _, bg = imgui.color_edit3("background", list(opts.background))
        opts.background = tuple(bg)
        _, opts.surfels = imgui.checkbox("surfels", opts.surfels)
        if s.source.mesh is not None:
            _, opts.wireframe = imgui.checkbox("wireframe", opts.wireframe)
            imgui.same_line()
            _, opts.coarse = imgui.checkbox("coarse surfels", opts.coarse)
            imgui.same_line()
            _, opts.normals = imgui.checkbox("normals", opts.normals)

    def _body_panel(self) -> None:
        ctl = self.state.controls
        if imgui.button("canonical pose"):
            ctl.reset_pose()
            self._motion_index = 0
        imgui.text("shape")
        for i, label in enumerate(ctl.shape_space.labels[:10]):  # SMPL-X: the first betas
            lo, hi = ctl.shape_range(i)
            changed, v = imgui.slider_float(label, float(ctl.shape[i]), lo, hi)
            if changed:
                ctl.set_shape(i, v)
        for side, name in enumerate(("left hand", "right hand")):
            changed, v = imgui.slider_float(f"{name} closed", ctl.hand_curl[side], 0.0, 1.0)
            if changed:
                ctl.set_hand_curl(side, v)
        if imgui.tree_node("expression"):
            for i, label in enumerate(ctl.expression_space.labels):
                changed, v = imgui.slider_float(label, float(ctl.expression[i]), 0.0, 1.0)
                if changed:
                    ctl.set_expression(i, v)
            imgui.tree_pop()

    def _record_panel(self) -> None:
        s, rs = self.state, self.state.record
        _, rs.out = imgui.input_text("output (.mp4/.gif/dir)", rs.out)
        _, rs.width = imgui.input_int("width", rs.width)
        _, rs.height = imgui.input_int("height", rs.height)
        _, rs.fps = imgui.input_float("fps", rs.fps)
        _, rs.seconds = imgui.input_float("turntable seconds", rs.seconds)
        if imgui.button("add camera key"):
            s.add_record_key()
        imgui.same_line()
        if imgui.button("clear keys"):
            rs.keys.keys.clear()
            rs.keys.times.clear()
        imgui.text(f"{len(rs.keys.keys)} keys (fewer than 2: turntable)")
        if s.recorder is None:
            if imgui.button("record"):
                try:
                    s.start_recording()
                except (GmaError, OSError, ValueError) as exc:
                    s.message = str(exc)
        else:
            imgui.progress_bar(s.recorder.progress, imgui.ImVec2(-1, 0),
                               f"{s.recorder.frame}/{s.recorder.num_frames}")

    def _edit_panel(self) -> None:
        s, w = self.state, self.window
        changed, i = imgui.combo("tool", _TOOLS.index(w.tool), list(_TOOLS))
        if changed:
            w.tool = _TOOLS[i]
        imgui.text("drag to select; Shift adds, Ctrl subtracts")
        _, s.front_only = imgui.checkbox("front-facing only", s.front_only)
        imgui.text(f"{len(s.scene.selection)} faces selected")
        body = s.source.body
        for name in list(body.regions) + list(body.face_label_names):
            if imgui.small_button(name):
                s.select_part(name, "add" if imgui.get_io().key_shift else "replace")
            imgui.same_line()
        imgui.new_line()
        if imgui.button("clear"):
            s.clear_selection()
        imgui.same_line()
        if imgui.button("invert"):
            s.invert_selection()
        _, self.selection_path = imgui.input_text("file", self.selection_path)
        for label, action in (("save", s.save_selection), ("load", s.load_selection)):
            if imgui.button(label):
                try:
                    action(self.selection_path)
                except (GmaError, OSError, ValueError) as exc:
                    s.message = str(exc)
            imgui.same_line()
        imgui.new_line()
