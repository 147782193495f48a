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
