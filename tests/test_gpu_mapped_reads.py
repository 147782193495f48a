"""Read-backs in place on CPU adapters (gma/gpu/mapped_reads.py): the public render's images and gradients
are views of mapped buffers, which must stay untouched while they live, come back for reuse once they
are gone, and equal what the staging path reads."""

import gc

import pytest
import torch
from render_helpers import default_camera, torch_scene

from gma.gpu import GpuContext
from gma.gpu.mapped_reads import packed_ranges
from gma.render import rasterize


@pytest.fixture(scope="module")
def in_place(gpu):
    if not gpu.reads_in_place:
        pytest.skip("the adapter does not read in place (a GPU, or mappable-primary-buffers missing)")
    return gpu


@pytest.fixture(scope="module")
def staging(in_place):
    """A second context on the same adapter that reads through a staging buffer."""
    return GpuContext.create(disable_features=("mappable-primary-buffers",))


def _render(ctx, seed: int, grad: bool = False):
    cam = default_camera(96, 80)
    scene = torch_scene(300, seed=seed)
    params = {k: v.clone().requires_grad_(grad) for k, v in scene.items()}
    out = rasterize(params["means"], params["quats"], params["scales"], params["opacities"], params["colors"],
                    torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height, ctx=ctx)
    if grad:
        (out.color.square().mean() + out.depth.mean() + out.alpha.mean()).backward()
    return out, params


def test_kept_outputs_stay_as_they_were_while_later_renders_run(in_place):
    first, params = _render(in_place, seed=1, grad=True)
    images = [t.detach().clone() for t in (first.color, first.alpha, first.normal, first.depth)]
    grads = [params[k].grad.clone() for k in sorted(params)]
    for seed in (2, 3, 4):   # more renders and backward passes than the pool keeps free buffers for
        _render(in_place, seed=seed, grad=True)
    assert all(torch.equal(a, b) for a, b in zip(images, (first.color, first.alpha, first.normal, first.depth)))
    assert all(torch.equal(a, params[k].grad) for a, k in zip(grads, sorted(params)))
    assert not torch.equal(first.color, _render(in_place, seed=2)[0].color)


def test_buffers_come_back_once_their_arrays_are_gone(in_place):
    reads = in_place.mapped_reads
    for size in range(40, 52):   # more buffers of other sizes than are kept: the most recently returned stay
        arrays = reads.read(reads.take(size << 16, "other"), 64)
        del arrays
    out, _ = _render(in_place, seed=5)
    del out
    gc.collect()
    before = reads.reused
    out, _ = _render(in_place, seed=5)
    assert reads.reused > before
    out.color[:] = 0.5   # the caller's memory: writable, and nothing reads it back
    assert float(out.color.mean()) == 0.5


def test_the_same_images_and_gradients_as_through_staging(in_place, staging):
    assert not staging.reads_in_place
    a, pa = _render(in_place, seed=6, grad=True)
    b, pb = _render(staging, seed=6, grad=True)
    for x, y in zip((a.color, a.alpha, a.normal, a.depth), (b.color, b.alpha, b.normal, b.depth)):
        assert torch.equal(x, y)
    for k in pa:
        assert torch.equal(pa[k].grad, pb[k].grad), k


def test_packed_ranges_are_aligned_and_disjoint():
    ranges, total = packed_ranges([16, 1000, 4, 256], 256)
    assert ranges == [(0, 16), (256, 1000), (1280, 4), (1536, 256)] and total == 1792
    assert packed_ranges([], 256) == ([], 256)
