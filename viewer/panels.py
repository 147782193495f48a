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
from viewer.actions import TOOLS, report

__all__ = ["Panels"]

_KEYS = {glfw.KEY_BACKSPACE: imgui.Key.backspace, glfw.KEY_DELETE: imgui.Key.delete, glfw.KEY_ENTER: imgui.Key.enter,
         glfw.KEY_LEFT: imgui.Key.left_arrow, glfw.KEY_RIGHT: imgui.Key.right_arrow, glfw.KEY_HOME: imgui.Key.home,
         glfw.KEY_END: imgui.Key.end, glfw.KEY_TAB: imgui.Key.tab, glfw.KEY_ESCAPE: imgui.Key.escape,
         glfw.KEY_UP: imgui.Key.up_arrow, glfw.KEY_DOWN: imgui.Key.down_arrow}


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
        self.stamp_path = ""
        self.donor_path = ""
        self.save_as_path = ""
        self._hex: str | None = None  # the hex field's text while it is being typed

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
            self._confirm_close()
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
        q = self.window.last_quality
        imgui.text("still (full frame shown again)" if q is None else f"frame: {q.label()}")
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
        if self.state.edit is not None and imgui.collapsing_header("Edit"):
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
            playing = s.motion_label
            if playing not in items:
                items.append(playing)  # a motion file given with --motion or loaded below
            changed, index = imgui.combo("motion", items.index(playing), items)
            if changed and items[index] != playing:
                s.play_motion(None if index == 0 else items[index])
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
        ed = self.state.edit
        if ed is not None and ed.can_edit:
            if imgui.button("keep shape and expression"):
                report(self.state, ed.keep_body)
            imgui.same_line()
            if imgui.button("back to the avatar's"):
                ed.reset_body()

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
        """Select / Paint / Stamp / Transfer / History / File. Each widget calls one EditTools method
        (errors become the status line, see :func:`viewer.actions.report`)."""
        self._select_section()
        if not self.state.edit.can_edit:
            imgui.text("(open a fitted .gma to paint, stamp and transfer)")
            return
        if imgui.collapsing_header("Paint", imgui.TreeNodeFlags_.default_open):
            self._paint_section()
        if imgui.collapsing_header("Stamp"):
            self._stamp_section()
        if imgui.collapsing_header("Transfer"):
            self._transfer_section()
        if imgui.collapsing_header("History", imgui.TreeNodeFlags_.default_open):
            self._history_section()
        if imgui.collapsing_header("File", imgui.TreeNodeFlags_.default_open):
            self._file_section()

    def _select_section(self) -> None:
        s, w, ed = self.state, self.window, self.state.edit
        changed, i = imgui.combo("tool", TOOLS.index(w.tool), list(TOOLS))
        if changed:
            w.tool = TOOLS[i]
        imgui.text(f"{len(ed.selection)} faces selected  (drag: replace, Shift adds, Ctrl subtracts)")
        _, ed.brush.radius = imgui.slider_float("brush radius (px)", ed.brush.radius, 2.0, 200.0)
        _, ed.brush.falloff = imgui.slider_float("brush falloff", ed.brush.falloff, 0.0, 1.0)
        _, ed.wand_tolerance = imgui.slider_float("wand tolerance", ed.wand_tolerance, 0.0, 0.5)
        _, ed.mirror = imgui.checkbox("mirror left-right (X)", ed.mirror)
        if imgui.tree_node("regions"):
            body = ed.body
            for k, name in enumerate(list(body.regions) + list(body.face_label_names)):
                if k % 6:
                    imgui.same_line()
                if imgui.small_button(name):
                    report(s, ed.select_region, name, "add" if imgui.get_io().key_shift else "replace")
            imgui.tree_pop()
        for k, (label, action) in enumerate((("grow", ed.grow), ("shrink", ed.shrink), ("invert", ed.invert),
                                             ("clear", ed.clear))):
            if k:
                imgui.same_line()
            if imgui.button(label):
                report(s, action)
        _, self.selection_path = imgui.input_text("selection file", self.selection_path)
        for label, action in (("save##sel", s.save_selection), ("load##sel", s.load_selection)):
            if imgui.button(label):
                report(s, action, self.selection_path)
            imgui.same_line()
        imgui.new_line()

    def _paint_section(self) -> None:
        s, w, ed = self.state, self.window, self.state.edit
        changed, col = imgui.color_edit3("colour", list(ed.color))
        if changed:
            ed.set_color(col)
        changed, text = imgui.input_text("hex", self._hex if self._hex is not None else ed.hex_color,
                                         imgui.InputTextFlags_.enter_returns_true)
        self._hex = text if imgui.is_item_active() else None
        if changed:
            report(s, ed.set_color, text)
            self._hex = None
        if imgui.button("fill selection (F)"):
            report(s, ed.fill)
        imgui.same_line()
        if imgui.button("paint brush (P)"):
            w.tool = "paint"
        imgui.same_line()
        if imgui.button("eyedropper (I)"):
            w.tool = "eyedropper"
        if ed.last_stroke.update_ms:
            ms = sorted(ed.last_stroke.update_ms)[len(ed.last_stroke.update_ms) // 2]
            imgui.text(f"last stroke: {ed.last_stroke.updates} updates, median {ms:.0f} ms")

    def _stamp_section(self) -> None:
        s, w, ed = self.state, self.window, self.state.edit
        _, self.stamp_path = imgui.input_text("image file", self.stamp_path)
        imgui.same_line()
        if imgui.button("load##stamp") and report(s, ed.load_stamp, self.stamp_path) is not None:
            w.tool = "stamp"
        imgui.text("or drop an image on the window; drag moves, Shift+drag rotates, wheel scales")
        if ed.stamp is not None:
            st = ed.stamp
            _, st.size = imgui.slider_float("size (px)", st.size, 4.0, 1024.0)
            _, st.rotation = imgui.slider_float("rotation", st.rotation, -180.0, 180.0)
            _, ed.stamp_in_selection = imgui.checkbox("only in the selection", ed.stamp_in_selection)
            if imgui.button("apply stamp (Enter)"):
                report(s, ed.apply_stamp, w.size)

    def _transfer_section(self) -> None:
        s, ed = self.state, self.state.edit
        _, self.donor_path = imgui.input_text("donor .gma", self.donor_path)
        imgui.same_line()
        if imgui.button("open##donor"):
            report(s, ed.load_donor, self.donor_path)
        imgui.text(f"donor: {ed.donor_name or '(none; or drop a .gma on the window)'}")
        for what in ("geo", "tex", "both"):
            if imgui.radio_button(what, ed.transfer_what == what):
                ed.transfer_what = what
            imgui.same_line()
        if imgui.button("transfer to selection"):
            report(s, ed.transfer)

    def _history_section(self) -> None:
        s, ed = self.state, self.state.edit
        if imgui.button("undo (Ctrl+Z)"):
            report(s, ed.undo)
        imgui.same_line()
        if imgui.button("redo (Ctrl+Shift+Z)"):
            report(s, ed.redo)
        records = ed.history()
        imgui.text(f"{len(records)} records; click one to revert to it")
        if imgui.selectable("0  (as opened / fitted)", len(records) == 0)[0]:
            report(s, ed.revert, 0)
        for k, line in enumerate(records[-12:], start=max(len(records) - 12, 0) + 1):
            if imgui.selectable(f"{k}  {line.strip()}", k == len(records))[0]:
                report(s, ed.revert, k)

    def _file_section(self) -> None:
        s, ed = self.state, self.state.edit
        name = str(ed.path) if ed.path else "(none)"
        imgui.text(f"{name}{' (unsaved edits)' if ed.dirty else ''}")
        if imgui.button("save (Ctrl+S)"):
            report(s, ed.save)
        _, self.save_as_path = imgui.input_text("save as", self.save_as_path)
        imgui.same_line()
        if imgui.button("save##as"):
            report(s, ed.save, self.save_as_path)

    def _confirm_close(self) -> None:
        """The unsaved-edits question, while the window holds a close request."""
        if not self.window.confirm_close:
            return
        if not imgui.is_popup_open("Unsaved edits"):
            imgui.open_popup("Unsaved edits")
        if imgui.begin_popup_modal("Unsaved edits", None, imgui.WindowFlags_.always_auto_resize)[0]:
            imgui.text("The avatar has unsaved edits.")
            ed = self.state.edit
            if imgui.button("save and close") and report(self.state, ed.save) is not None:
                self.window.discard_and_close()
                imgui.close_current_popup()
            imgui.same_line()
            if imgui.button("discard"):
                self.window.discard_and_close()
                imgui.close_current_popup()
            imgui.same_line()
            if imgui.button("cancel"):
                self.window.cancel_close()
                imgui.close_current_popup()
            imgui.end_popup()
