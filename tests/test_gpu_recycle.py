"""Recycled buffers (gma/gpu/recycle.py): the public render call reuses a finished call's buffers, and a
render on buffers that still hold another scene's values gives exactly what fresh buffers give."""

from __future__ import annotations

import gc
import threading

import numpy as np
import torch
from render_helpers import default_camera, torch_scene

from gma.gpu.context import STORAGE
from gma.gpu.recycle import BufferRecycler
from gma.render import rasterize


def _render_and_grads(gpu, scene, cam, upstream):
    params = [scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")]
    out = rasterize(*params, torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height, ctx=gpu)
    loss = (out.color * upstream["color"]).sum() + (out.alpha * upstream["alpha"]).sum()
    loss.backward()
    images = [getattr(out, k).detach().numpy().copy() for k in ("color", "alpha", "normal", "depth")]
    return images, [p.grad.numpy().copy() for p in params]


def test_render_on_recycled_buffers_equals_fresh_buffers(gpu, monkeypatch):
    cam = default_camera(72, 56)
    scene = torch_scene(400, seed=3)
    scene["means"][:40, 2] = -1.0      # behind the camera: culled, their gradients written as zeros
    other = torch_scene(400, seed=8)   # same sizes, other values: its buffers come back holding them
    rng = np.random.default_rng(0)
    upstream = {"color": torch.from_numpy(rng.normal(size=(56, 72, 3)).astype(np.float32)),
                "alpha": torch.from_numpy(rng.normal(size=(56, 72, 1)).astype(np.float32))}
    recycler = gpu.recycler
    with monkeypatch.context() as m:   # recycling off: fresh, zero-filled buffers
        m.setattr(recycler, "enabled", False)
        fresh_images, fresh_grads = _render_and_grads(gpu, scene, cam, upstream)
    _render_and_grads(gpu, other, cam, {k: -2 * v for k, v in upstream.items()})
    gc.collect()
    # On CPU adapters the images and gradients go to mappable buffers of their own (gma/gpu/mapped_reads.py).
    def reused() -> int:
        return recycler.reused + (gpu.mapped_reads.reused if gpu.reads_in_place else 0)

    before = reused()
    images, grads = _render_and_grads(gpu, scene, cam, upstream)
    assert reused() - before >= 20, "the second call should run on the first call's buffers"
    for name, got, want in zip(("color", "alpha", "normal", "depth"), images, fresh_images):
        np.testing.assert_array_equal(got, want, err_msg=name)
    for name, got, want in zip(("means", "quats", "scales", "opacities", "colors"), grads, fresh_grads):
        np.testing.assert_array_equal(got, want, err_msg=name)


def test_steady_render_loop_allocates_nothing(gpu):
    cam = default_camera(64, 48)
    scene = torch_scene(300, seed=5)
    upstream = {"color": torch.ones(48, 64, 3), "alpha": torch.zeros(48, 64, 1)}
    for _ in range(2):   # warm-up: pipelines, scratch, capacity hints
        _render_and_grads(gpu, scene, cam, upstream)
    start = gpu.allocated_bytes
    for _ in range(3):
        _render_and_grads(gpu, scene, cam, upstream)
    assert gpu.allocated_bytes - start < 1024, "a steady loop should reuse its buffers (only tiny ones new)"


def test_recycler_keeps_at_most_its_budget_and_matches_size_and_usage(gpu):
    recycler = BufferRecycler(gpu, keep_bytes=4096)

    class Owner:
        pass

    owner = Owner()
    bufs = [recycler.take(2048, f"b{i}", STORAGE) for i in range(3)]
    recycler.release_with(owner, bufs)
    del owner
    gc.collect()
    assert recycler.free_bytes == 4096   # the oldest went first
    assert recycler.take(2048, "again", STORAGE) is bufs[2]
    assert recycler.take(1024, "other size", STORAGE) not in bufs
    assert recycler.take(2048, "last", STORAGE | 0) is bufs[1]
    assert recycler.free_bytes == 0


def test_recycling_switched_off(gpu):
    recycler = BufferRecycler(gpu, enabled=False)
    first = recycler.take(1024, "a", STORAGE)
    recycler.give_back([first])
    assert recycler.free_bytes == 0
    assert recycler.take(1024, "b", STORAGE) is not first


def test_owner_collected_while_the_recycler_holds_its_lock_does_not_deadlock(gpu):
    """Garbage collection can free an owner in the middle of take() on the same thread; its finalizer
    must not wait for the lock that thread holds."""
    recycler = BufferRecycler(gpu)

    class Owner:
        pass

    bufs = [recycler.take(2048, "b", STORAGE)]
    holder = [Owner()]
    recycler.release_with(holder[0], bufs)

    def busy_then_collect():
        with recycler._lock:   # as inside take() when a collection frees the owner
            holder.clear()     # the owner's finalizer runs now, on this thread

    worker = threading.Thread(target=busy_then_collect, daemon=True)
    worker.start()
    worker.join(10)
    assert not worker.is_alive(), "the finalizer waited for the lock its own thread held"
    assert recycler.free_bytes == 2048
    assert recycler.take(2048, "again", STORAGE) is bufs[0]


def test_stale_gradient_records_never_reach_the_sums(gpu, monkeypatch):
    """On lavapipe the backward's gradient records are scratch that is never cleared: only the records
    its cleared slots point to are summed, all written by that backward (tile_walk_bwd.wgsl). A run of
    backwards with growing and shrinking record sizes (more intersections; normal and depth losses add
    colour slots), each over the last one's records, must give exactly what a fresh rasterizer gives."""
    from gma.render import api

    rast = api.rasterizer_for(gpu)
    if not rast.options.grad_records:
        return   # records are the lavapipe path; elsewhere the atomics' buffers are fresh per call
    cam = default_camera(64, 48)
    rng = np.random.default_rng(1)

    def step(scene, with_normal_depth):
        params = [scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")]
        out = rasterize(*params, torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height,
                        ctx=gpu)
        loss = (out.color * upstream["color"]).sum()
        if with_normal_depth:
            loss = loss + (out.normal * upstream["normal"]).sum() + (out.depth * upstream["depth"]).sum()
        loss.backward()
        return [p.grad.numpy().copy() for p in params]

    upstream = {k: torch.from_numpy(rng.normal(size=(48, 64, c)).astype(np.float32))
                for k, c in (("color", 3), ("normal", 3), ("depth", 1))}
    small, large = torch_scene(150, seed=11), torch_scene(600, seed=12)
    for scene, normal_depth in ((small, False), (large, False), (large, True), (small, True), (large, False)):
        grads = step(scene, normal_depth)
        with monkeypatch.context() as m:   # a fresh rasterizer: fresh records, cleared before use
            m.setattr(api, "_rasterizers", {})
            fresh = step(scene, normal_depth)
        for name, got, want in zip(("means", "quats", "scales", "opacities", "colors"), grads, fresh):
            np.testing.assert_array_equal(got, want, err_msg=name)
