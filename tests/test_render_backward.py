"""WGSL backward passes against the torch reference's autograd (float64), on lavapipe.

Tolerances. The GPU accumulates float32 gradients in another order than the reference (with atomics in
an arbitrary order, or on lavapipe per-intersection records summed in a fixed one) and recovers the
transmittance before each surfel by division, T_i = T_{i+1} / (1 - alpha_i), which amplifies rounding
by up to 1 / T (T >= 1e-4 by construction); the reference works in float64 front to back. Measured
agreement is ~1e-5 of the largest gradient of each input. We require every gradient entry to be within
2e-3 * max|reference gradient| except for at most 0.5% of entries (pixels whose alpha or transmittance
sits within float32 rounding of the 1/255 or 1e-4 thresholds take the other branch in one renderer),
and those within 5e-2 * max.
"""

from __future__ import annotations

import gc
from dataclasses import replace

import numpy as np
import pytest
import torch
from render_helpers import assert_image_close, default_camera, special_surfels, torch_scene

from gma.render import RasterOptions, SurfelBuffers, SurfelRasterizer, rasterize, rasterize_reference, read_outputs
from gma.render.gpu_sort import LANE_MAX_DIGIT_BITS
from gma.render.reference import project_reference

pytestmark = pytest.mark.gpu
NAMES = ("means", "quats", "scales", "opacities", "colors")
REL_TOL, OUTLIER_FRACTION, HARD_REL_TOL = 2e-3, 5e-3, 5e-2


def reference_grads(scene, cam, upstream, background=None):
    t = [scene[k].detach().double().requires_grad_(True) for k in NAMES]
    bg = None if background is None else torch.as_tensor(background).double()
    out = rasterize_reference(*t, torch.from_numpy(cam.viewmat).double(), torch.from_numpy(cam.K).double(),
                              cam.width, cam.height, bg)
    loss = sum((out[k] * torch.from_numpy(u).double()).sum() for k, u in upstream.items() if u is not None)
    loss.backward()
    return {k: (np.zeros(x.shape) if x.grad is None else x.grad.numpy()) for k, x in zip(NAMES, t)}


def random_upstream(cam, channels=3, seed=0, which=("color", "alpha", "normal", "depth")):
    rng = np.random.default_rng(seed)
    shapes = {"color": channels, "alpha": 1, "normal": 3, "depth": 1}
    return {k: (rng.normal(size=(cam.height, cam.width, c)).astype(np.float32) if k in which else None)
            for k, c in shapes.items()}


def variant(gpu, subgroups=True, float_atomics=True, records=True) -> RasterOptions:
    """The adapter's options with the subgroup rasterizers, float atomics or gradient records switched off
    (each only where the adapter has it: the variants other adapters run)."""
    best = RasterOptions.for_context(gpu)
    if not subgroups:   # the plain rasterizers (GPUs): no tile walk, hence no records
        best = replace(best, subgroups=False, tile_walk=False, grad_records=False)
    return replace(best, float_atomics=float_atomics and best.float_atomics,
                   grad_records=records and best.grad_records)


def gpu_grads(gpu, scene, cam, upstream, background=None, subgroups=True, float_atomics=True, records=True):
    rast = SurfelRasterizer(gpu, variant(gpu, subgroups, float_atomics, records))
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
    state = rast.forward(buffers, cam, background)
    g = rast.backward(state, buffers, upstream["color"], upstream["alpha"], upstream["normal"], upstream["depth"])
    return {k: getattr(g, k) for k in NAMES}


def assert_grads_close(got, want):
    for name in NAMES:
        scale = max(float(np.abs(want[name]).max()), 1e-8)
        err = np.abs(got[name] - want[name]) / scale
        frac = float((err > REL_TOL).mean())
        assert frac <= OUTLIER_FRACTION, f"{name}: {frac:.3%} entries off by > {REL_TOL} x max (max {err.max():.3g})"
        assert err.max() <= HARD_REL_TOL, f"{name}: worst error {err.max():.3g} x max|grad|"


@pytest.mark.parametrize("n,size", [(1, (21, 17)), (255, (64, 64)),
                                    pytest.param(2000, (100, 75), marks=pytest.mark.slow)])
def test_gradients_match_reference(gpu, n, size):
    scene = torch_scene(n, seed=n + 1)
    cam = default_camera(*size)
    up = random_upstream(cam, seed=n)
    assert_grads_close(gpu_grads(gpu, scene, cam, up), reference_grads(scene, cam, up))


@pytest.mark.parametrize("subgroups,float_atomics,records", [(True, True, True), (True, True, False),
                                                             (True, False, False), (False, True, False),
                                                             (False, False, False)])
def test_every_kernel_variant(gpu, subgroups, float_atomics, records):
    """Subgroup (CPU adapters) and plain (GPU) variants; gradient records (lavapipe), native float atomics
    and compare-and-swap."""
    scene = torch_scene(400, seed=4)
    cam = default_camera(45, 37)
    up = random_upstream(cam, seed=1)
    bg = np.array([0.3, 0.1, 0.7], np.float32)
    got = gpu_grads(gpu, scene, cam, up, bg, subgroups=subgroups, float_atomics=float_atomics, records=records)
    assert_grads_close(got, reference_grads(scene, cam, up, bg))


@pytest.mark.parametrize("which", [("color",), ("color", "alpha", "normal", "depth")])
def test_gradient_records_reproducible_and_equal_to_atomics(gpu, which):
    """On lavapipe the subgroup backward sums per-intersection records in a fixed order: the same
    gradients, bit for bit, on every run, and the atomics' sums up to float32 reordering. The images do
    not depend on whether the forward kept the record index (its keys carry more than the tile)."""
    if not RasterOptions.for_context(gpu).grad_records:
        pytest.skip("gradient records need lavapipe's subgroup rasterizer")
    scene = torch_scene(3000, seed=21, spread=0.6, scale_range=(0.02, 0.15))
    cam = default_camera(96, 80)
    up = random_upstream(cam, seed=7, which=which)
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
    rasterizers = {records: SurfelRasterizer(gpu, variant(gpu, records=records)) for records in (True, False)}

    def run(records, one_pass_sort=True):
        rast = rasterizers[records]
        # Records lie at emission indices, which the keys carry through any tile sort: here the
        # sort is also made to take several passes (lavapipe's lane sort takes one).
        rast.sorter.max_digit_bits = LANE_MAX_DIGIT_BITS if one_pass_sort else 3
        state = rast.forward(buffers, cam)
        assert (state.records is not None) == records
        images = read_outputs(gpu, state)
        g = rast.backward(state, buffers, up["color"], up["alpha"], up["normal"], up["depth"])
        return images, {k: getattr(g, k) for k in NAMES}

    images, first = run(True)
    num_isects = rasterizers[True].forward(buffers, cam).num_isects
    assert num_isects > 3 * 3000 // 2, "the scene should spread surfels over several tiles each"
    for one_pass_sort in (True, False, True):
        _, again = run(True, one_pass_sort)
        for k in NAMES:
            assert np.array_equal(again[k], first[k]), k
    plain_images, atomics = run(False)
    for k in ("color", "alpha", "normal", "depth"):
        assert np.array_equal(getattr(images, k), getattr(plain_images, k)), k
    for k in NAMES:
        scale = float(np.abs(atomics[k]).max())
        assert np.abs(first[k] - atomics[k]).max() <= 1e-5 * scale, k


def test_surfel_texels_change_nothing(gpu):
    """The tile walks read projected surfels and colours, and project_bwd the gradient records, from
    texture copies (gma/render/surfel_texels.py): images and gradients equal those from the buffers bit
    for bit, over several texture rows (5000
    surfels: 4.9 rows of projections, 1.2 of colours) and after the textures grew for a larger scene."""
    rast = SurfelRasterizer(gpu)
    if not rast.options.grad_records:
        pytest.skip("the surfel textures serve lavapipe's tile walks")
    cam = default_camera(80, 64)
    for n in (5000, 700):
        scene = torch_scene(n, seed=n, spread=0.8, scale_range=(0.02, 0.12))
        up = random_upstream(cam, seed=3, which=("color", "normal"))
        buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
        results = []
        # Buffers (textures that hold nothing); textures; textures too small for these surfels and records
        # (the buffers then).
        for capacity, max_texels in ((0, 0), (None, None), (4096, 1 << 14)):
            rast.texels = type(rast.texels)(gpu)   # the true capacities
            if capacity is not None:
                rast.texels.capacity, rast.texels.max_texels = capacity, max_texels
            state = rast.forward(buffers, cam)
            images = read_outputs(gpu, state)
            g = rast.backward(state, buffers, up["color"], up["alpha"], up["normal"], up["depth"])
            results.append((images, g))
        (images_a, grads_a), *others = results
        for images_b, grads_b in others:
            for k in ("color", "alpha", "normal", "depth"):
                assert np.array_equal(getattr(images_a, k), getattr(images_b, k)), (n, k)
            for k in NAMES:
                assert np.array_equal(getattr(grads_a, k), getattr(grads_b, k)), (n, k)
        assert np.abs(grads_a.means).sum() > 0


def test_a_backward_reads_the_layout_its_forward_wrote(gpu):
    """With the tile walk, projection writes the walks' layout (each surfel's colour beside its T rows, the
    normal and depth apart: surfel_texels.wgsl). A forward state records the variant it was rendered with,
    and a backward run by a rasterizer of other options reads it as written: the same gradients as its own
    rasterizer's."""
    if not RasterOptions.for_context(gpu).grad_records:
        pytest.skip("the walks' layout serves lavapipe's tile walks")
    cam = default_camera(72, 56)
    scene = torch_scene(1800, seed=21, spread=0.8, scale_range=(0.02, 0.15))
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
    walked = SurfelRasterizer(gpu)
    per_subgroup = SurfelRasterizer(gpu, replace(walked.options, tile_walk=False, grad_records=False))
    for which in (("color",), ("color", "normal", "depth")):   # without and with normal/depth gradients
        up = random_upstream(cam, seed=8, which=which)
        state = walked.forward(buffers, cam)
        assert state.proj.walk_layout and state.records is not None
        own = walked.backward(state, buffers, up["color"], up["alpha"], up["normal"], up["depth"])
        other = per_subgroup.backward(state, buffers, up["color"], up["alpha"], up["normal"], up["depth"])
        for k in NAMES:
            assert np.array_equal(getattr(own, k), getattr(other, k)), (which, k)
        assert np.abs(own.colors).sum() > 0 and np.abs(own.means).sum() > 0


def test_work_queues_give_the_same_results_whatever_their_workgroup_count(gpu):
    """On lavapipe projection, emission, the tile walks and project_bwd take their work from a queue, one
    workgroup per driver thread (common/work_queue.wgsl): any workgroup count, including more than there
    are tiles, gives bit for bit the images and gradients of one workgroup per tile and per 256 surfels."""
    best = RasterOptions.for_context(gpu)
    if not best.grad_records:
        pytest.skip("the work queues serve lavapipe")
    cam = default_camera(88, 72)   # 6 x 5 tiles
    scene = torch_scene(1500, seed=33, spread=0.8, scale_range=(0.02, 0.15))
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
    up = random_upstream(cam, seed=4, which=("color", "alpha"))
    results = []
    for queued, workgroups in ((False, 1), (True, 1), (True, 2), (True, 5), (True, 64)):
        assert best.work_queues
        rast = SurfelRasterizer(gpu, replace(best, work_queues=queued, queue_workgroups=workgroups))
        state = rast.forward(buffers, cam)
        results.append((read_outputs(gpu, state),
                        rast.backward(state, buffers, up["color"], up["alpha"], None, None)))
    (images, grads), others = results[0], results[1:]
    for other_images, other_grads in others:
        for k in ("color", "alpha", "normal", "depth"):
            assert np.array_equal(getattr(images, k), getattr(other_images, k)), k
        for k in NAMES:
            assert np.array_equal(getattr(grads, k), getattr(other_grads, k)), k
    assert images.alpha.min() < 0.5 < images.alpha.max() and np.abs(grads.means).sum() > 0


def test_interleaved_renders_keep_their_own_texels(gpu):
    """A replayed render's surfel textures are its state's (TexelLease) until the state is gone: renders
    of other scenes between a forward and its backward change nothing, and given-back textures serve
    later renders."""
    rast = SurfelRasterizer(gpu)
    cam = default_camera(64, 48)
    scenes = [torch_scene(n, seed=40 + n, spread=0.8, scale_range=(0.02, 0.12)) for n in (900, 1500)]
    buffers = [SurfelBuffers.from_arrays(gpu, *(sc[k].numpy() for k in NAMES)) for sc in scenes]
    up = random_upstream(cam, seed=5, which=("color",))

    def grads(state, b):
        g = rast.backward(state, b, up["color"], None, None, None)
        return [getattr(g, k).copy() for k in NAMES]

    alone = [grads(rast.forward(b, cam), b) for b in buffers]
    first, second = rast.forward(buffers[0], cam), rast.forward(buffers[1], cam)
    rast.forward(buffers[1], cam, replay=False)   # a viewer-style render in between
    if rast.options.grad_records:
        assert first.texel_lease is not None and first.texel_lease is not second.texel_lease
    for got, want in ((grads(second, buffers[1]), alone[1]), (grads(first, buffers[0]), alone[0])):
        for name, a, b in zip(NAMES, got, want):
            assert np.array_equal(a, b), name
    leased = [first.texel_lease, second.texel_lease]
    del first, second
    gc.collect()
    again = rast.forward(buffers[0], cam)
    if rast.options.grad_records:   # a given-back lease serves it
        assert any(again.texel_lease is held for held in leased)
    for name, a, b in zip(NAMES, grads(again, buffers[0]), alone[0]):
        assert np.array_equal(a, b), name


def test_gradient_records_only_where_they_fit(gpu):
    """Records need a tile id below the key's number field and a buffer binding that holds them; a
    render beyond either (or with more than 4 channels: the plain rasterizer) falls back to atomics."""
    rast = SurfelRasterizer(gpu)
    if not rast.options.grad_records:
        pytest.skip("gradient records need lavapipe's subgroup rasterizer")
    assert rast._records_for(default_camera(512, 512), 3, 224_000)
    assert rast._records_for(default_camera(4112, 64), 3, 1000)   # 257 x 4 tiles
    assert not rast._records_for(default_camera(4112, 4112), 3, 1000)  # 66049 tiles > 65536
    assert not rast._records_for(default_camera(64, 64), 5, 1000)      # plain rasterizer
    too_many = gpu.max_binding_bytes // 80 + 1
    assert not rast._records_for(default_camera(64, 64), 3, too_many)


def test_context_without_float_atomics(gpu_no_float_atomics):
    ctx = gpu_no_float_atomics
    assert not ctx.has_float_atomics
    scene = torch_scene(300, seed=8)
    cam = default_camera(33, 29)
    up = random_upstream(cam, seed=2)
    assert_grads_close(gpu_grads(ctx, scene, cam, up), reference_grads(scene, cam, up))


@pytest.mark.slow
def test_edge_cases_and_heavy_overlap(gpu):
    """Behind-camera, near-plane, edge-on, huge, zero-scale and invisible surfels, plus a dense stack."""
    scene = special_surfels()
    cam = default_camera(50, 38)
    up = random_upstream(cam, seed=3)
    assert_grads_close(gpu_grads(gpu, scene, cam, up), reference_grads(scene, cam, up))
    dense = torch_scene(1500, seed=12, spread=0.3, scale_range=(0.05, 0.3))
    up = random_upstream(cam, seed=4)
    assert_grads_close(gpu_grads(gpu, dense, cam, up), reference_grads(dense, cam, up))


def far_centred_surfels() -> dict[str, torch.Tensor]:
    """Large tilted surfels whose circle almost reaches the camera plane: each covers most of a 40x30 image
    while the centre of its image conic lies hundreds to ~10^5 pixels away (checked below)."""
    tilts, sizes = np.radians([60.0, 88.0, 80.0, 88.0]), [2.3, 2.0, 2.05, 2.0012]
    quats = np.array([[np.cos(a / 2), 0.0, np.sin(a / 2), 0.0] for a in tilts], np.float32)
    rng = np.random.default_rng(8)
    scene = {"means": np.array([[0.1, 0.05, 2.0], [0.05, 0.0, 2.0], [-0.05, 0.1, 2.0], [0.0, -0.1, 2.0]], np.float32),
             "quats": quats, "scales": np.array([[s, s] for s in sizes], np.float32),
             "opacities": np.array([0.5, 0.4, 0.6, 0.3], np.float32),
             "colors": rng.uniform(0, 1, (4, 3)).astype(np.float32)}
    return {k: torch.from_numpy(v) for k, v in scene.items()}


@pytest.mark.parametrize("subgroups", [True, False])
def test_surfels_whose_conic_centre_lies_far_outside_the_image(gpu, subgroups):
    """The rasterizers evaluate each surfel's ray-splat intersection about a reference point: the projected
    centre clamped near the image (render/ray_plane.wgsl). About a centre thousands of pixels away the
    linear form would cancel large terms; images and gradients must still match the float64 reference."""
    scene = far_centred_surfels()
    cam = default_camera(40, 30)
    t = [scene[k].double() for k in NAMES]
    view, K = torch.from_numpy(cam.viewmat).double(), torch.from_numpy(cam.K).double()
    _, mu2d, _, _, valid = project_reference(*t[:4], view, K)
    far = (mu2d[:, 0] < -100) | (mu2d[:, 0] > cam.width + 100)
    assert bool(valid.all()) and int(far.sum()) == 4 and float(mu2d.abs().max()) > 5e4, mu2d
    ref = rasterize_reference(*t, view, K, cam.width, cam.height)
    assert float((ref["alpha"] > 0.1).double().mean()) > 0.5   # the surfels cover the image
    rast = SurfelRasterizer(gpu, variant(gpu, subgroups))
    buffers = SurfelBuffers.from_arrays(gpu, *(scene[k].numpy() for k in NAMES))
    out = read_outputs(gpu, rast.forward(buffers, cam))
    assert_image_close("color", out.color, ref["color"].numpy())
    assert_image_close("alpha", out.alpha, ref["alpha"].numpy())
    up = random_upstream(cam, seed=11)
    got = gpu_grads(gpu, scene, cam, up, subgroups=subgroups)
    assert_grads_close(got, reference_grads(scene, cam, up))


@pytest.mark.parametrize("subgroups", [True, False])
@pytest.mark.parametrize("which", [("color",), ("alpha",), ("normal", "depth"), ("depth",)])
def test_upstream_on_a_subset_of_outputs(gpu, which, subgroups):
    """Without normal or depth upstream the kernels drop those terms and bindings (NORMAL_DEPTH_GRADS)."""
    scene = torch_scene(200, seed=6)
    cam = default_camera(30, 26)
    up = random_upstream(cam, seed=5, which=which)
    got = gpu_grads(gpu, scene, cam, up, subgroups=subgroups)
    assert_grads_close(got, reference_grads(scene, cam, up))


def test_autograd_function(gpu):
    """Through torch autograd: needs_input_grad respected, None for what was not asked, background too."""
    scene = torch_scene(150, seed=9)
    cam = default_camera(24, 20)
    colors = scene["colors"].clone().requires_grad_(True)
    means = scene["means"].clone().requires_grad_(True)
    bg = torch.tensor([0.2, 0.5, 0.9], requires_grad=True)
    out = rasterize(means, scene["quats"], scene["scales"], scene["opacities"], colors,
                    torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height, bg, ctx=gpu)
    loss = out.color.square().mean() + 0.1 * out.depth.mean()
    loss.backward()
    t = [scene[k].double().requires_grad_(k in ("means", "colors")) for k in NAMES]
    bg_ref = bg.detach().double().requires_grad_(True)
    ref = rasterize_reference(*t, torch.from_numpy(cam.viewmat).double(), torch.from_numpy(cam.K).double(),
                              cam.width, cam.height, bg_ref)
    (ref["color"].square().mean() + 0.1 * ref["depth"].mean()).backward()
    for got, want in ((means.grad, t[0].grad), (colors.grad, t[4].grad), (bg.grad, bg_ref.grad)):
        scale = float(want.abs().max())
        assert float((got.double() - want).abs().max()) <= REL_TOL * scale + 1e-9
    assert scene["quats"].grad is None


def test_reference_gradcheck():
    """float64 gradcheck of the reference itself, on a scene with no alpha near the thresholds."""
    g = torch.Generator().manual_seed(0)
    n = 3
    means = (torch.rand(n, 3, generator=g, dtype=torch.float64) - 0.5) * 0.4 + torch.tensor([0, 0, 3.0],
                                                                                           dtype=torch.float64)
    quats = torch.randn(n, 4, generator=g, dtype=torch.float64)
    scales = torch.rand(n, 2, generator=g, dtype=torch.float64) * 0.2 + 0.3
    opac = torch.rand(n, generator=g, dtype=torch.float64) * 0.5 + 0.3
    cols = torch.rand(n, 3, generator=g, dtype=torch.float64)
    cam = default_camera(6, 5)
    view = torch.from_numpy(cam.viewmat).double()
    K = torch.from_numpy(cam.K).double()

    def f(m, q, s, o, c):
        out = rasterize_reference(m, q, s, o, c, view, K, cam.width, cam.height)
        return out["color"], out["alpha"], out["normal"], out["depth"]

    inputs = tuple(x.requires_grad_(True) for x in (means, quats, scales, opac, cols))
    assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-5, rtol=1e-4)
