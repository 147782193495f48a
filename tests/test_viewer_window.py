"""The viewer window under Xvfb (started by the test session): the presented frame equals the offscreen
render of the same view, and mouse input (fed through the window's glfw callbacks, as glfw delivers it)
orbits the camera and selects the faces inside a box."""

from __future__ import annotations

import numpy as np
import pytest
import viewer_helpers

from gma.edit import Selection
from gma.view.selection import faces_in_box

small_body_source = viewer_helpers.small_body_source  # fixtures
xvfb_display = viewer_helpers.xvfb_display

pytestmark = [pytest.mark.gpu, pytest.mark.window]

W, H = 160, 120
# The window shows the same bytes as the offscreen texture (same passes, non-sRGB targets); allow a
# rounding step in case a driver converts through another format on presentation.
TOLERANCE = 2


@pytest.fixture()
def window(gpu, small_body_source, xvfb_display):
    glfw = pytest.importorskip("glfw")
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    state = ViewerState(gpu, small_body_source)
    try:
        win = ViewerWindow(state, W, H, panels=False)
    except RuntimeError as exc:
        pytest.skip(f"no window: {exc}")
    assert glfw.get_framebuffer_size(win.window) == (W, H)
    yield win
    win.close()


def drag(win, button, start, end, steps=4, mods=0):
    """A press-move-release gesture delivered through the callbacks glfw calls."""
    import glfw

    win._on_cursor(win.window, *start)
    win._on_button(win.window, button, glfw.PRESS, mods)
    for t in np.linspace(0, 1, steps + 1)[1:]:
        win._on_cursor(win.window, *(np.asarray(start) + t * (np.asarray(end) - np.asarray(start))))
        win.draw_frame()  # the outline of a box drag is drawn while dragging
    win._on_button(win.window, button, glfw.RELEASE, mods)


def test_window_frame_matches_offscreen_render(window):
    window.draw_frame()
    shot = window.screenshot()
    state = window.state
    offscreen = state.renderer.render_image(state.scene, state.camera(W, H))
    assert shot.shape == offscreen.shape == (H, W, 4)
    diff = np.abs(shot[..., :3].astype(int) - offscreen[..., :3].astype(int))
    assert diff.max() <= TOLERANCE, f"window differs from offscreen by up to {diff.max()}"
    assert (shot[..., :3] < 240).any(-1).mean() > 0.05  # and it is not just background


fitted_avatar_file = viewer_helpers.fitted_avatar_file  # fixture


@pytest.mark.parametrize("size", [(160, 120), (320, 240)])
def test_fitted_avatar_opens_whole_on_the_first_frame(gpu, fitted_avatar_file, xvfb_display, size):
    """A fitted avatar opened fresh, canonical pose, no interaction: the first presented frame and the
    frames shown again after it equal an offscreen render from a renderer of its own (which checks that no
    surfel was dropped)."""
    pytest.importorskip("glfw")
    from gma.view import FrameRenderer
    from gma.view.source import avatar_source
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    w, h = size
    state = ViewerState(gpu, avatar_source(gpu, fitted_avatar_file))
    win = ViewerWindow(state, w, h, panels=False)
    try:
        first = win.screenshot()
        later = [win.screenshot() for _ in range(2)]
    finally:
        win.close()
    offscreen = FrameRenderer(gpu).render_image(state.scene, state.camera(w, h), complete=True)
    for shot in (first, *later):
        diff = np.abs(shot[..., :3].astype(int) - offscreen[..., :3].astype(int))
        assert diff.max() <= TOLERANCE, f"window differs from offscreen by up to {diff.max()}"
    assert (first[..., :3] < 240).any(-1).mean() > 0.05


def test_orbit_drag_moves_the_camera(window):
    import glfw

    before = window.screenshot()
    eye = window.state.orbit.eye.copy()
    drag(window, glfw.MOUSE_BUTTON_LEFT, (40, 60), (100, 60))
    assert window.state.orbit.azimuth != 0.0
    assert not np.allclose(window.state.orbit.eye, eye)
    after = window.screenshot()
    assert np.abs(after.astype(int) - before.astype(int)).max() > 50


def test_box_selection_selects_faces_inside_and_highlights_them(window):
    import glfw

    window.tool = "box"
    before = window.screenshot()
    drag(window, glfw.MOUSE_BUTTON_LEFT, (60, 20), (100, 70))
    state = window.state
    src = state.source
    expected = Selection.box(state.edit.view((W, H)), (60, 20, 100, 70)).faces.numpy()
    in_box = faces_in_box(src.posed_vertices(), src.body.faces.numpy(), state.camera(W, H), (60, 20, 100, 70))
    assert 0 < len(expected) < in_box.sum()  # only the visible faces of the front-facing ones in the box
    assert in_box[expected].all()
    np.testing.assert_array_equal(state.scene.selection, expected)
    after = window.screenshot()
    changed = np.abs(after.astype(int) - before.astype(int)).max(-1) > 10
    ys, xs = np.nonzero(changed)
    assert len(xs) and xs.min() >= 55 and xs.max() <= 105 and ys.min() >= 15 and ys.max() <= 75
    # Shift adds, Ctrl subtracts.
    drag(window, glfw.MOUSE_BUTTON_LEFT, (60, 80), (100, 110), mods=glfw.MOD_SHIFT)
    assert set(expected) < set(state.scene.selection.tolist())
    drag(window, glfw.MOUSE_BUTTON_LEFT, (0, 0), (160, 120), mods=glfw.MOD_CONTROL)
    assert len(state.scene.selection) == 0


def test_panels_draw_over_the_frame(gpu, small_body_source, xvfb_display):
    pytest.importorskip("imgui_bundle")
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    win = ViewerWindow(ViewerState(gpu, small_body_source), 320, 240, panels=True)
    try:
        assert win.ui is not None
        win.draw_frame()
        shot = win.screenshot()
        offscreen = win.state.renderer.render_image(win.state.scene, win.state.camera(320, 240))
        assert np.abs(shot.astype(int) - offscreen.astype(int)).max() > 50  # the panel covers part of it
    finally:
        win.close()


small_avatar_file = viewer_helpers.small_avatar_file  # fixtures
avatar_state = viewer_helpers.avatar_state


@pytest.fixture()
def avatar_window(avatar_state, xvfb_display):
    pytest.importorskip("glfw")
    from viewer.window import ViewerWindow

    win = ViewerWindow(avatar_state, W, H, panels=False)
    yield win
    win.close()


def key(win, k, mods=0):
    import glfw

    win._on_key(win.window, k, 0, glfw.PRESS, mods)
    win._on_key(win.window, k, 0, glfw.RELEASE, mods)


def assert_window_equals_offscreen(win):
    """The presented frame equals the offscreen render of the same view with the same overlays."""
    shot = win.screenshot()
    lines, images = win._overlays()
    state = win.state
    off = state.renderer.render_image(state.scene, state.camera(W, H), lines=lines, images=images)
    diff = np.abs(shot[..., :3].astype(int) - off[..., :3].astype(int))
    assert diff.max() <= TOLERANCE, f"window differs from offscreen by up to {diff.max()}"
    return shot


@pytest.mark.slow
def test_paint_stroke_undo_save_in_the_window(avatar_window):
    import glfw

    win, state = avatar_window, avatar_window.state
    ed = state.edit
    before = win.screenshot()
    key(win, glfw.KEY_P)
    assert win.tool == "paint"
    ed.set_color("#000000")
    ed.brush.radius = 8
    drag(win, glfw.MOUSE_BUTTON_LEFT, (70, 40), (90, 50), steps=4)  # one stroke, frames drawn while dragging
    assert ed.background  # the window solves beside the frame loop
    ed.wait()
    win.draw_frame()  # the frame after the stroke's last solve landed (cheap frames may outrun the solve)
    assert ed.last_stroke.dabs >= 2 and ed.last_stroke.updates >= 1
    assert len(state.source.avatar.history) == 1
    assert win._shown_title.endswith("avatar.gma*")  # dirty marker
    shot = assert_window_equals_offscreen(win)
    changed = np.abs(shot.astype(int) - before.astype(int)).max(-1) > 40
    ys, xs = np.nonzero(changed)
    assert len(xs) and xs.min() >= 55 and xs.max() <= 105
    key(win, glfw.KEY_Z, glfw.MOD_CONTROL)
    assert len(state.source.avatar.history) == 0
    key(win, glfw.KEY_Z, glfw.MOD_CONTROL | glfw.MOD_SHIFT)
    assert len(state.source.avatar.history) == 1
    key(win, glfw.KEY_S, glfw.MOD_CONTROL)
    win.draw_frame()
    assert not ed.dirty and win._shown_title.endswith("avatar.gma")
    from gma.avatar import Avatar

    assert len(Avatar.load(state.source.path).history) == 1


@pytest.mark.slow
def test_dropped_image_is_a_stamp_preview_applied_with_enter(avatar_window, tmp_path):
    import glfw
    import imageio.v3 as iio

    win, state = avatar_window, avatar_window.state
    img = np.zeros((16, 16, 4), np.uint8)
    img[..., 1] = img[..., 3] = 255
    iio.imwrite(tmp_path / "green.png", img)
    before = win.screenshot()
    win._on_drop(win.window, [str(tmp_path / "green.png")])
    assert win.tool == "stamp" and state.edit.stamp is not None
    state.edit.stamp.size = 16
    drag(win, glfw.MOUSE_BUTTON_LEFT, (80, 60), (80, 50), steps=2)  # move the preview up 10 px
    assert state.edit.stamp.centre == pytest.approx((80, 50))
    shot = assert_window_equals_offscreen(win)  # the preview quad, on screen as offscreen
    assert shot[50, 80, 1] > before[50, 80, 1] + 30 or before[50, 80, 1] > 200
    key(win, glfw.KEY_ENTER)
    state.edit.wait()
    assert state.source.avatar.history[-1]["op"] == "stamp"
    key(win, glfw.KEY_N)  # navigate: no preview
    after = win.screenshot()
    assert int(after[50, 80, 1]) - int(after[50, 80, 0]) > 60


@pytest.mark.slow
def test_closing_with_unsaved_edits_asks_first(avatar_window):
    import glfw

    win = avatar_window
    win.state.edit.select_box((60, 20, 100, 70), (W, H))
    win.state.edit.fill()
    win.state.edit.wait()
    win._on_close_request(win.window)
    assert not win.should_close and "unsaved" in win.state.message
    win._on_close_request(win.window)  # a second close discards
    glfw.set_window_should_close(win.window, True)
    assert win.should_close


@pytest.mark.slow
def test_edit_panels_draw_with_an_avatar(avatar_state, xvfb_display):
    pytest.importorskip("imgui_bundle")
    from viewer.window import ViewerWindow

    win = ViewerWindow(avatar_state, 320, 240, panels=True)
    try:
        win.tool = "stamp"
        from gma.edit import solid_shape

        avatar_state.edit.set_stamp_image(solid_shape("circle", (1, 0, 0), 16))
        for _ in range(3):
            win.draw_frame()
        win.confirm_close = True  # the unsaved-edits question
        win.draw_frame()
        assert win.screenshot().shape == (240, 320, 4)
    finally:
        win.close()
