"""Cheaper frames while the view changes: the GPU subset of surfels against its numpy twin, the quality
governor's choices, the renderer's reuse of a settled frame, and the window refining to a frame identical
to today's full-quality render once input stops."""

from __future__ import annotations

import numpy as np
import pytest
import viewer_helpers

from gma.core.camera import Camera
from gma.view.quality import FULL, LADDER, FrameQuality, QualityGovernor

small_body_source = viewer_helpers.small_body_source  # fixtures
xvfb_display = viewer_helpers.xvfb_display


# -- the subset pass ------------------------------------------------------------------------------------
@pytest.mark.parametrize("n, stride, channels, spread", [(1000, 4, 3, True), (1001, 3, 3, False), (7, 8, 5, True),
                                                        (300, 2, 1, False)])
def test_subset_matches_numpy(gpu, n, stride, channels, spread):
    from gma.render.subset import SurfelSubset, spread_order, subset_count, subset_reference
    from gma.render.surfels import SurfelBuffers

    rng = np.random.default_rng(n + stride)
    arrays = {"means": rng.normal(size=(n, 3)), "quats": rng.normal(size=(n, 4)),
              "scales": rng.uniform(0.01, 0.1, (n, 2)), "opacities": rng.uniform(0, 1, n),
              "colors": rng.uniform(0, 1, (n, channels))}
    arrays = {k: v.astype(np.float32) for k, v in arrays.items()}
    src = SurfelBuffers.from_arrays(gpu, *arrays.values())
    order = spread_order(n, rng.integers(0, max(1, n // 3), n)) if spread else None
    enc = gpu.device.create_command_encoder()
    out = SurfelSubset(gpu).encode(enc, src, stride, order)
    gpu.submit(enc)
    want = subset_reference(arrays, stride, order)
    m = subset_count(n, stride)
    assert out.count == m == len(want["means"])
    for name, width in (("means", 3), ("quats", 4), ("scales", 2), ("opacities", 1), ("colors", channels)):
        got = gpu.read(getattr(out, name), np.float32, m * width).reshape(want[name].shape)
        if name == "scales":  # WGSL's sqrt may be a few ulp off (spec: inherited from inverseSqrt)
            np.testing.assert_allclose(got, want[name], rtol=2e-6, err_msg=name)
        else:  # copies: exact
            np.testing.assert_array_equal(got, want[name], err_msg=name)


def test_spread_order_covers_every_face_before_repeating_one():
    from gma.render.subset import spread_order

    faces = np.repeat(np.arange(50), 4)  # face-major, 4 surfels per face
    order = spread_order(200, faces, seed=1)
    assert sorted(order.tolist()) == list(range(200))
    for stride in (1, 2, 4):
        kept = faces[order[: 200 // stride]]
        counts = np.bincount(kept, minlength=50)
        assert counts.min() == counts.max() == 4 // stride, stride  # every face keeps the same share
    half = np.sort(faces[order[:25]])  # fewer surfels than faces: distinct faces, not a run of rows
    assert len(np.unique(half)) == 25 and not np.array_equal(half, np.arange(25))
    assert sorted(spread_order(10).tolist()) == list(range(10))
    with pytest.raises(ValueError):
        spread_order(3, [0, 1])


def test_subset_of_stride_one_is_the_source(gpu):
    from gma.render.subset import SurfelSubset
    from gma.render.surfels import SurfelBuffers

    src = SurfelBuffers.allocate(gpu, 10)
    enc = gpu.device.create_command_encoder()
    assert SurfelSubset(gpu).encode(enc, src, 1) is src
    with pytest.raises(ValueError, match="stride"):
        SurfelSubset(gpu).encode(enc, src, 0)


# -- the governor -----------------------------------------------------------------------------------------
def test_governor_reuses_only_a_settled_full_frame():
    g = QualityGovernor(target_fps=10)
    assert g.next_frame(changed=False) == FULL  # nothing on screen yet
    g.frame_done(50)
    assert g.next_frame(changed=False) is None  # settled: show it again
    g.frame_done(1)
    assert g.next_frame(changed=True) == LADDER[0]
    g.invalidate()
    assert g.next_frame(changed=False) == FULL


def test_governor_steps_down_while_slow_and_back_up_when_fast():
    g = QualityGovernor(target_fps=10)  # budget 100 ms
    costs = {0: 400.0, 1: 200.0, 2: 120.0, 3: 60.0, 4: 30.0, 5: 20.0, 6: 10.0}
    seen = []
    for _ in range(12):
        g.next_frame(changed=True)
        seen.append(g.level)
        g.frame_done(costs[g.level])
    assert seen[:4] == [0, 1, 2, 3]  # one step per slow frame
    assert set(seen[4:]) <= {3, 4}, seen  # settles where frames fit the budget (3: 60 ms)
    assert g.level == 3
    # The machine gets 8x faster: the governor climbs back to full quality.
    for _ in range(12):
        g.next_frame(changed=True)
        g.frame_done(costs[g.level] / 8)
    assert g.level == 0


def test_governor_settled_frame_is_full_even_when_interactive_level_is_low():
    g = QualityGovernor(target_fps=10)
    g.level = 4
    q = g.next_frame(changed=True)
    assert q == LADDER[4] and not q.is_full
    g.frame_done(90)
    assert g.next_frame(changed=False) == FULL  # the view settled on a cheap frame: refine
    g.frame_done(500)  # a slow refine does not move the interactive level
    assert g.level == 4
    assert g.next_frame(changed=False) is None


def test_governor_without_adaptation_draws_full_frames():
    g = QualityGovernor(adaptive=False)
    for _ in range(3):
        assert g.next_frame(changed=True) == FULL
        g.frame_done(10_000)
    assert g.level == 0
    with pytest.raises(ValueError):
        QualityGovernor(target_fps=0)


def test_frame_quality_sizes_and_labels():
    assert FrameQuality(0.5, 4).image_size(801, 600) == (400, 300)
    assert FULL.image_size(7, 5) == (7, 5) and FULL.label() == "full"
    assert FrameQuality(0.75, 8).label() == "1/8 surfels at 75%"


# -- the renderer ------------------------------------------------------------------------------------------
def _offscreen(gpu, w, h):
    import wgpu

    return gpu.device.create_texture(size=(w, h, 1), format="rgba8unorm",
                                     usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC)


def test_renderer_reuses_a_settled_frame_and_redraws_on_change(gpu, small_body_source):
    from gma.view import FrameRenderer, OrbitCamera, Scene
    from gma.view.renderer import read_texture

    w, h = 96, 72
    scene = Scene(small_body_source)
    r = FrameRenderer(gpu)
    orbit = OrbitCamera.framing(*small_body_source.bounds(), up_axis=small_body_source.up_axis)
    cam = orbit.camera(w, h)
    tex = _offscreen(gpu, w, h)
    full = r.render_image(scene, cam)
    drawn = r.surfel_frames
    r.draw(scene, cam, tex.create_view(), "rgba8unorm", quality=None)
    assert r.surfel_frames == drawn, "an unchanged view must not run the surfel renderer"
    np.testing.assert_array_equal(read_texture(gpu, tex), full)
    # A cheaper frame: drawn, smaller, close to the full one but not equal.
    r.draw(scene, cam, tex.create_view(), "rgba8unorm", quality=FrameQuality(0.5, 4))
    cheap = read_texture(gpu, tex)
    assert r.surfel_frames == drawn + 1 and r._image_size == (48, 36)
    diff = np.abs(cheap[..., :3].astype(float) - full[..., :3].astype(float))
    assert 0 < diff.mean() < 25, diff.mean()  # same body, same place: only softer
    # None after a cheap frame, or after the view moved, draws the full frame again.
    r.draw(scene, cam, tex.create_view(), "rgba8unorm", quality=None)
    np.testing.assert_array_equal(read_texture(gpu, tex), full)
    orbit.orbit(20, 0)
    moved = orbit.camera(w, h)
    r.draw(scene, moved, tex.create_view(), "rgba8unorm", quality=None)
    assert r.surfel_frames == drawn + 3
    np.testing.assert_array_equal(read_texture(gpu, tex), r.render_image(scene, moved))


def test_camera_resized_keeps_the_rays():
    cam = Camera.look_at((0, 0, 3), (0, 0, 0), width=200, height=100)
    small = cam.resized(50, 25)
    px, _ = cam.project(np.array([[0.3, -0.2, 0.1]]))
    spx, _ = small.project(np.array([[0.3, -0.2, 0.1]]))
    np.testing.assert_allclose(spx * 4, px, rtol=1e-5)
    assert cam.resized(200, 100) is cam


# -- the window ----------------------------------------------------------------------------------------------
@pytest.mark.window
def test_window_moves_cheaply_then_settles_on_the_full_frame(gpu, small_body_source, xvfb_display):
    pytest.importorskip("glfw")
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    w, h = 160, 120
    state = ViewerState(gpu, small_body_source)
    try:
        win = ViewerWindow(state, w, h, panels=False, target_fps=1e6)  # an impossible target: go cheap
    except RuntimeError as exc:
        pytest.skip(f"no window: {exc}")
    try:
        for _ in range(4):
            state.orbit_by(10, 0)
            win.draw_frame()
        assert win.last_quality is not None and not win.last_quality.is_full
        win.draw_frame()  # input stopped: refine
        assert win.last_quality == FULL and not win.idle
        drawn = state.renderer.surfel_frames
        win.draw_frame()
        assert win.last_quality is None and win.idle and state.renderer.surfel_frames == drawn
        shot = win.screenshot()
        ref = state.renderer.render_image(state.scene, state.camera(w, h))
        np.testing.assert_array_equal(shot[..., :3], ref[..., :3])
    finally:
        win.close()
