"""WGSL forward renderer against the torch reference on lavapipe (tolerances: tests/render_helpers.py)."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
import torch
from render_helpers import assert_image_close, default_camera, special_surfels, torch_scene

from gma.render import RasterOptions, SurfelBuffers, SurfelRasterizer, rasterize, rasterize_reference

pytestmark = pytest.mark.gpu


def subgroup_variant(gpu, subgroups: bool) -> RasterOptions:
    """The adapter's options with the subgroup rasterizers (CPU adapters; the tile walk with 8 lanes) or the
    plain ones (GPUs); skips where the adapter's subgroups cannot run them."""
    best = RasterOptions.for_context(gpu)
    if not subgroups:
        return replace(best, subgroups=False, tile_walk=False, grad_records=False)
    if not (gpu.has_subgroups and 1 <= gpu.subgroup_size <= 32):
        pytest.skip("adapter has no subgroups the rasterizers can use")
    tile_walk = gpu.subgroup_size == 8
    return replace(best, subgroups=True, tile_walk=tile_walk, grad_records=tile_walk and best.grad_records)


def render_both(scene, camera, background=None, ctx=None):
    args = (scene["means"], scene["quats"], scene["scales"], scene["opacities"], scene["colors"],
            torch.from_numpy(camera.viewmat), torch.from_numpy(camera.K), camera.width, camera.height)
    got = rasterize(*args, background=background, ctx=ctx)
    want = rasterize_reference(*args, background=background)
    return got, want


def compare(got, want):
    depth_scale = float(want["depth"].abs().max()) if want["depth"].numel() else 1.0
    assert_image_close("color", got.color.numpy(), want["color"].numpy())
    assert_image_close("alpha", got.alpha.numpy(), want["alpha"].numpy())
    assert_image_close("normal", got.normal.numpy(), want["normal"].numpy())
    assert_image_close("depth", got.depth.numpy(), want["depth"].numpy(), scale=max(depth_scale, 1.0))


@pytest.mark.parametrize("n", [0, 1, 255, 2000])
@pytest.mark.parametrize("size", [(64, 64), (100, 75)])
def test_random_scene_matches_reference(gpu, n, size):
    scene = torch_scene(n, seed=n)
    got, want = render_both(scene, default_camera(*size), ctx=gpu)
    compare(got, want)
    assert got.color.shape == (size[1], size[0], 3)
    if n == 2000:
        assert float(got.alpha.mean()) > 0.2, "the scene should cover much of the image"


def test_edge_cases_match_reference(gpu):
    """Behind the camera, near plane, edge-on, tiny, huge (crossing the camera plane), zero scale,
    below the alpha threshold."""
    got, want = render_both(special_surfels(), default_camera(100, 75), ctx=gpu)
    compare(got, want)


def test_background_and_channels(gpu):
    for channels in (1, 3, 5):
        scene = torch_scene(300, seed=7, channels=channels)
        bg = torch.linspace(0.2, 0.8, channels)
        got, want = render_both(scene, default_camera(70, 50), background=bg, ctx=gpu)
        compare(got, want)


@pytest.mark.parametrize("channels", [1, 2, 4])
def test_channel_counts_in_whole_rows(gpu, channels):
    """Widths that are a multiple of 4, where the tile walk stores each image row's four pixels at once
    (write_block_pixels in rasterize_fwd.wgsl: the channels interleaved by shuffles), and a height that
    ends inside a block."""
    scene = torch_scene(400, seed=11, channels=channels)
    bg = torch.linspace(0.1, 0.9, channels)
    got, want = render_both(scene, default_camera(68, 44), background=bg, ctx=gpu)
    compare(got, want)


def test_more_surfels_on_one_tile_than_a_batch(gpu):
    """600 faint overlapping surfels on one tile: compositing must continue across staged batches."""
    rng = np.random.default_rng(3)
    n = 600
    means = np.zeros((n, 3), np.float32)
    means[:, :2] = rng.uniform(-0.02, 0.02, (n, 2))
    means[:, 2] = rng.uniform(3.0, 4.0, n)
    scene = {
        "means": torch.from_numpy(means),
        "quats": torch.tensor([[1.0, 0, 0, 0]]).repeat(n, 1),
        "scales": torch.full((n, 2), 0.05),
        "opacities": torch.full((n,), 0.01),
        "colors": torch.from_numpy(rng.uniform(0, 1, (n, 3)).astype(np.float32)),
    }
    got, want = render_both(scene, default_camera(32, 32), ctx=gpu)
    compare(got, want)
    assert float(want["alpha"].max()) > 0.9, "the stack should nearly saturate the centre"


def test_saturated_tiles_stop_early_but_match(gpu):
    """Many opaque layers: most pixels saturate; output must still match exactly."""
    scene = torch_scene(3000, seed=11, scale_range=(0.3, 0.6), spread=2.5, depth=5.0)
    scene["opacities"] = torch.full((3000,), 0.99)
    got, want = render_both(scene, default_camera(48, 40), ctx=gpu)
    compare(got, want)
    assert float(want["alpha"].median()) > 0.999


def test_texture_path_matches_buffer_path(gpu):
    import wgpu

    scene = torch_scene(500, seed=5)
    cam = default_camera(40, 24)
    bg = np.array([0.1, 0.3, 0.5], np.float32)
    rast = SurfelRasterizer(gpu)
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in
                                               ("means", "quats", "scales", "opacities", "colors")))
    texture = gpu.device.create_texture(
        size=(cam.width, cam.height, 1), format=wgpu.TextureFormat.rgba8unorm,
        usage=wgpu.TextureUsage.STORAGE_BINDING | wgpu.TextureUsage.COPY_SRC)
    rast.render_to_texture(buffers, cam, texture.create_view(), gpu.upload(bg, "bg"))
    raw = gpu.device.queue.read_texture({"texture": texture}, {"bytes_per_row": 4 * cam.width,
                                                                "rows_per_image": cam.height},
                                        (cam.width, cam.height, 1))
    rgba = np.frombuffer(raw, np.uint8).reshape(cam.height, cam.width, 4) / 255.0
    want = rasterize(*(scene[k] for k in ("means", "quats", "scales", "opacities", "colors")),
                     torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height,
                     background=torch.from_numpy(bg), ctx=gpu)
    # rgba8 quantisation: half a step of 1/255 plus rounding.
    assert np.abs(rgba[..., :3] - want.color.numpy().clip(0, 1)).max() <= 0.6 / 255 + 1e-6
    assert np.abs(rgba[..., 3:] - want.alpha.numpy()).max() <= 0.6 / 255 + 1e-6


@pytest.mark.parametrize("case", ["deep", "saturated"])
def test_tile_walk_matches_the_per_subgroup_variant_bit_for_bit(gpu, case):
    """With 8-lane subgroups one subgroup composites a whole tile (tile_walk_fwd.wgsl); it blends the same
    surfels in the same order and batches as the per-subgroup variant that other subgroup sizes run, so
    images (buffer path, replayed or not, and the texture path) agree bit for bit: on tiles with more
    intersections than a batch, and on tiles that saturate early."""
    import wgpu

    from gma.render import read_outputs

    best = RasterOptions.for_context(gpu)
    if not best.tile_walk:
        pytest.skip("the tile walk needs the subgroup rasterizer with 8 lanes")
    if case == "deep":
        scene = torch_scene(2500, seed=4, scale_range=(0.05, 0.3), spread=0.4)
        scene["opacities"] = torch.full((2500,), 0.02)
    else:
        scene = torch_scene(3000, seed=11, scale_range=(0.3, 0.6), spread=2.5, depth=5.0)
        scene["opacities"] = torch.full((3000,), 0.99)
    cam = default_camera(56, 40)
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in
                                               ("means", "quats", "scales", "opacities", "colors")))
    bg = gpu.upload(np.array([0.2, 0.4, 0.6], np.float32), "bg")
    results = []
    for walk in (False, True):
        rast = SurfelRasterizer(gpu, replace(best, tile_walk=walk, grad_records=walk and best.grad_records))
        assert rast.raster_defines(3)["TILE_WALK"] == walk
        images = [read_outputs(gpu, rast.forward(buffers, cam, replay=replay)) for replay in (True, False)]
        texture = gpu.device.create_texture(
            size=(cam.width, cam.height, 1), format=wgpu.TextureFormat.rgba8unorm,
            usage=wgpu.TextureUsage.STORAGE_BINDING | wgpu.TextureUsage.COPY_SRC)
        rast.render_to_texture(buffers, cam, texture.create_view(), bg)
        raw = gpu.device.queue.read_texture({"texture": texture}, {"bytes_per_row": 4 * cam.width,
                                                                    "rows_per_image": cam.height},
                                            (cam.width, cam.height, 1))
        results.append((images, bytes(raw)))
    if case == "deep":
        state = SurfelRasterizer(gpu).forward(buffers, cam)
        ranges = gpu.read(state.tile_ranges, np.uint32, 2 * 4 * 3).reshape(-1, 2)
        assert int((ranges[:, 1] - ranges[:, 0]).max()) > 256, "some tile should hold more than a batch"
    (per_subgroup, tex_a), (walked, tex_b) = results
    for a, b in zip(per_subgroup, walked):
        for name in ("color", "alpha", "normal", "depth"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert tex_a == tex_b


def test_plain_and_subgroup_variants_agree(gpu):
    """The subgroup path (CPU adapters) and the plain path (GPUs) give the same image."""
    scene = torch_scene(1500, seed=2)
    cam = default_camera(64, 48)
    arrays = [scene[k].numpy() for k in ("means", "quats", "scales", "opacities", "colors")]
    outs = []
    for use in (False, True):
        if use and not (gpu.has_subgroups and 1 <= gpu.subgroup_size <= 32):
            pytest.skip("adapter has no subgroups the rasterizers can use")
        rast = SurfelRasterizer(gpu, subgroup_variant(gpu, use))
        from gma.render import read_outputs

        st = rast.forward(SurfelBuffers.from_arrays(gpu, *arrays), cam)
        outs.append(read_outputs(gpu, st))
    for name in ("color", "alpha", "normal", "depth"):
        np.testing.assert_allclose(getattr(outs[0], name), getattr(outs[1], name), atol=1e-5)


def test_intersection_block_bits_cover_every_reached_block(gpu):
    """The subgroup rasterizers skip a 4x2 pixel block of a tile where an intersection's block bits
    (block_bits.wgsl, packed above SURFEL_ID_BITS of its surfel id) leave it out: every block where the
    reference alpha of the surfel reaches 1/255 at some pixel centre must be in, and the bits must leave
    blocks out (else they prove nothing)."""
    if not gpu.has_subgroups:
        pytest.skip("adapter has no subgroups")
    from gma.render.layouts import tile_grid
    from gma.render.rasterizer import SURFEL_ID_BITS
    from gma.render.reference import project_reference, surfel_alpha_reference

    scene = special_surfels()
    more = torch_scene(300, seed=5)
    scene = {k: torch.cat([scene[k], more[k]]) for k in scene}
    cam = default_camera(80, 56)
    rast = SurfelRasterizer(gpu, subgroup_variant(gpu, True))
    arrays = [scene[k].numpy() for k in ("means", "quats", "scales", "opacities", "colors")]
    st = rast.forward(SurfelBuffers.from_arrays(gpu, *arrays), cam)
    tx, ty = tile_grid(cam.width, cam.height)
    packed = gpu.read(st.isect_ids, np.uint32, st.num_isects)
    ids, bits = packed & ((1 << SURFEL_ID_BITS) - 1), (packed >> SURFEL_ID_BITS).astype(np.int64)
    masks = ((bits & 15) | ((bits & 0xF0) << 12)) * 0x1111   # expand_block_bits
    ranges = gpu.read(st.tile_ranges, np.uint32, 2 * tx * ty).reshape(-1, 2)
    T, mu2d, _, _, _ = project_reference(scene["means"], scene["quats"], scene["scales"], scene["opacities"],
                                         torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K))
    ys, xs = np.mgrid[0:16, 0:16]
    block_bits = (1 << ((ys // 2) * 4 + xs // 4)).reshape(-1)
    left_out = 0
    for tile, (lo, hi) in enumerate(ranges):
        if lo == hi:
            continue
        px = np.stack([xs.reshape(-1) + 16 * (tile % tx), ys.reshape(-1) + 16 * (tile // tx)], -1)
        inside = (px[:, 0] < cam.width) & (px[:, 1] < cam.height)
        sids = ids[lo:hi].astype(np.int64)
        alpha = surfel_alpha_reference(T[sids], mu2d[sids], scene["opacities"][sids],
                                       torch.from_numpy(px + 0.5).float()).numpy()   # [256, k]
        # A small margin keeps pixels whose alpha is 1/255 to within rounding out of the check.
        reached = (alpha >= 1.0 / 255.0 * 1.001) & inside[:, None]
        needed = np.bitwise_or.reduce(np.where(reached, block_bits[:, None], 0), axis=0)
        got = masks[lo:hi]
        missing = needed & ~got
        assert not missing.any(), f"tile {tile}: blocks {missing[missing != 0]} reached but not in the bits"
        assert (got != 0).all(), f"tile {tile}: a listed intersection that reaches no block"
        left_out += int((got != 0xFFFFFFFF).sum())
    assert left_out > 0


def test_projection_stats_variants_agree(gpu):
    """Projection's frame stats (intersections wanted, smallest and largest listed depth key) are the
    same from subgroup reductions and from workgroup atomics, and match the tile counts it wrote."""
    if not gpu.has_subgroups:
        pytest.skip("adapter has no subgroups")
    scene = torch_scene(3000, seed=4)
    cam = default_camera(96, 64)
    arrays = [scene[k].numpy() for k in ("means", "quats", "scales", "opacities", "colors")]
    results = []
    for use in (False, True):
        rast = SurfelRasterizer(gpu, replace(RasterOptions.for_context(gpu), project_subgroups=use))
        st = rast.forward(SurfelBuffers.from_arrays(gpu, *arrays), cam)
        stats = gpu.read(st.proj.stats, np.uint32, 4)
        counts = gpu.read(st.proj.tile_counts, np.uint32, 3000)
        assert stats[1] == counts.sum() == st.num_isects
        results.append(stats[1:])
    np.testing.assert_array_equal(results[0], results[1])


@pytest.mark.parametrize("subgroups", [False, True])
def test_render_only_forward_matches_the_replayable_one(gpu, subgroups):
    """replay=False (what a render no gradient comes back to uses) gives bit-identical images from
    scratch buffers, for both rasterizer variants, and its state refuses a backward pass."""
    from gma.render import read_outputs

    if subgroups and not gpu.has_subgroups:
        pytest.skip("adapter has no subgroups")
    scene = torch_scene(2000, seed=5)
    cam = default_camera(80, 64)
    rast = SurfelRasterizer(gpu, subgroup_variant(gpu, subgroups))
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in ("means", "quats", "scales", "opacities",
                                                                           "colors")))
    kept = read_outputs(gpu, rast.forward(buffers, cam, np.array([0.2, 0.3, 0.4], np.float32)))
    state = rast.forward(buffers, cam, np.array([0.2, 0.3, 0.4], np.float32), replay=False)
    assert state.final_t is None and state.last is None
    only = read_outputs(gpu, state)
    for name in ("color", "alpha", "normal", "depth"):
        np.testing.assert_array_equal(getattr(only, name), getattr(kept, name))
    with pytest.raises(ValueError, match="replay=False"):
        rast.backward(state, buffers, np.zeros((cam.height, cam.width, 3), np.float32), None, None, None)


def test_public_render_without_gradients_matches_and_background_gradient_still_flows(gpu):
    scene = torch_scene(800, seed=6)
    cam = default_camera(48, 40)
    names = ("means", "quats", "scales", "opacities", "colors")
    view, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)
    plain = rasterize(*(scene[k] for k in names), view, K, cam.width, cam.height, ctx=gpu)
    graded = rasterize(*(scene[k].clone().requires_grad_() for k in names), view, K, cam.width, cam.height, ctx=gpu)
    assert torch.equal(plain.color, graded.color.detach()) and torch.equal(plain.depth, graded.depth.detach())
    # Only the background asks for a gradient: the render keeps no replay state and the gradient is exact.
    bg = torch.tensor([0.1, 0.5, 0.9], requires_grad=True)
    out = rasterize(*(scene[k] for k in names), view, K, cam.width, cam.height, background=bg, ctx=gpu)
    out.color.sum().backward()
    want = (1 - out.alpha.detach()).sum().expand(3)
    torch.testing.assert_close(bg.grad, want, rtol=1e-5, atol=1e-4)


def test_public_render_under_no_grad_keeps_no_replay_state(gpu, monkeypatch):
    """Surfels that require grad rendered under torch.no_grad (an evaluation during a fit): nothing is
    kept for a backward pass that cannot come, and the images are the same."""
    from gma.render import api

    scene = torch_scene(600, seed=8)
    cam = default_camera(40, 32)
    names = ("means", "quats", "scales", "opacities", "colors")
    view, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)
    params = [scene[k].clone().requires_grad_() for k in names]
    replays = []
    rast = api.rasterizer_for(gpu)
    original = rast.forward
    monkeypatch.setattr(rast, "forward", lambda *a, **k: replays.append(k["replay"]) or original(*a, **k))
    with torch.no_grad():
        quiet = rasterize(*params, view, K, cam.width, cam.height, ctx=gpu)
    graded = rasterize(*params, view, K, cam.width, cam.height, ctx=gpu)
    assert replays == [False, True]
    assert quiet.color.grad_fn is None and graded.color.grad_fn is not None
    assert torch.equal(quiet.color, graded.color.detach())


@pytest.mark.parametrize("read_images", [False, True])
def test_forward_sized_by_earlier_renders_runs_again_when_they_fall_short(gpu, read_images):
    """forward sizes the part after projection by what earlier renders needed (intersection capacity,
    depth-sort key bits) and runs it again with exact sizes when a render needs more: a first render
    and then a scene with more intersections and a wider depth range match a rasterizer that had
    already seen them, bit for bit, and the hints only grow. With read_images the images read together
    with the counts are those of the run that counted (after a rerun, the rerun's)."""
    from gma.render import read_outputs

    def buffers_of(scene):
        return SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in ("means", "quats", "scales",
                                                                            "opacities", "colors")))

    cam = default_camera(80, 64)
    flat = torch_scene(200, seed=3)
    flat["means"][:, 2] = flat["means"][:, 2] * 1e-3 + 3.0   # nearly one depth: few key bits
    flat, dense = buffers_of(flat), buffers_of(torch_scene(3000, seed=4))
    warm = SurfelRasterizer(gpu)
    for b in (flat, dense):
        warm.forward(b, cam)
    fresh = SurfelRasterizer(gpu)
    fresh.isect_capacity_hint = 16
    most, bits_seen = 16, []
    for b in (flat, dense, flat):
        bits = fresh.depth_bits_hint
        state = fresh.forward(b, cam, read_images=read_images)
        assert (state.host_images is not None) == read_images
        bits_seen.append(fresh.depth_bits_hint)
        most = max(most, state.num_isects)
        assert fresh.isect_capacity_hint == most and fresh.depth_bits_hint >= bits
        got, want = read_outputs(gpu, state), read_outputs(gpu, warm.forward(b, cam))
        for name in ("color", "alpha", "normal", "depth"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
    assert most > 4 * 200, "the dense scene should need more intersections than the first render"
    assert bits_seen[1] > bits_seen[0], "the dense scene should need more depth-key bits"
    assert fresh.depth_bits_hint == warm.depth_bits_hint > 1
