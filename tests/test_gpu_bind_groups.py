"""Reused bind groups (gma/gpu/bind_groups.py): the same buffers bound to the same pipeline give the same
bind group, and a freed buffer's bind groups go with it, so a new buffer that Python gives the freed one's
id never runs on the old buffer."""

from __future__ import annotations

import gc

import numpy as np

DOUBLE = """
@group(0) @binding(0) var<storage, read> src: array<f32>;
@group(0) @binding(1) var<storage, read_write> dst: array<f32>;
@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    if gid.x < arrayLength(&dst) { dst[gid.x] = 2.0 * src[gid.x]; }
}
"""


def _pipeline(gpu):
    module = gpu.device.create_shader_module(code=DOUBLE)
    return gpu.device.create_compute_pipeline(layout="auto", compute={"module": module, "entry_point": "main"})


def _dispatch(gpu, pipeline, resources, groups):
    """Run ``pipeline`` over ``groups`` workgroups with ``resources`` bound; returns the bind group."""
    bind = gpu.bind_group(pipeline, resources)
    enc = gpu.device.create_command_encoder()
    cp = enc.begin_compute_pass()
    cp.set_pipeline(pipeline)
    cp.set_bind_group(0, bind)
    cp.dispatch_workgroups(groups)
    cp.end()
    gpu.submit(enc)
    return bind


def _double(gpu, pipeline, src, dst, n):
    bind = _dispatch(gpu, pipeline, [src, dst], (n + 63) // 64)
    return bind, gpu.read(dst, np.float32, n)


def test_same_buffers_reuse_one_bind_group(gpu):
    pipeline = _pipeline(gpu)
    values = np.arange(100, dtype=np.float32)
    src, dst = gpu.upload(values, "src"), gpu.buffer(400, "dst")
    hits = gpu.bind_groups.hits
    first, out1 = _double(gpu, pipeline, src, dst, 100)
    second, out2 = _double(gpu, pipeline, src, dst, 100)
    assert second is first and gpu.bind_groups.hits == hits + 1
    np.testing.assert_array_equal(out1, 2 * values)
    np.testing.assert_array_equal(out2, 2 * values)
    # Another range of the same buffer is another bind group.
    ranged = gpu.bind_group(pipeline, [(src, 256, 144), dst])
    assert ranged is not first


def test_freed_buffer_takes_its_bind_groups_along(gpu):
    pipeline = _pipeline(gpu)
    dst = gpu.buffer(256, "dst")
    for k in range(12):   # buffers die and are made again: Python often hands out the same id
        values = np.full(64, float(k), np.float32)
        src = gpu.upload(values, "src")
        size_before = len(gpu.bind_groups)
        _, out = _double(gpu, pipeline, src, dst, 64)
        np.testing.assert_array_equal(out, 2 * values)   # never the previous buffer's values
        assert len(gpu.bind_groups) == size_before + 1
        del src
        gc.collect()
        assert len(gpu.bind_groups) == size_before   # the entry went with its buffer


class _FakeBuffer:
    """Stands in for a GPUBuffer in the cache's bookkeeping (any weak-referenceable object)."""


def test_new_buffer_with_a_dead_buffers_id_gets_its_own_bind_group(monkeypatch):
    """Python hands a freed object's id to the next object of its size, often at once; the cache must
    notice that the id now names another buffer even before it has dropped the dead buffer's entries.
    Whether CPython reuses the id depends on what else allocates meanwhile, so the cache is given an
    ``id`` under which every fake buffer shares one number: the collision, every time."""
    from gma.gpu import bind_groups
    from gma.gpu.bind_groups import BindGroupCache

    monkeypatch.setattr(bind_groups, "id", lambda obj: 7 if isinstance(obj, _FakeBuffer) else id(obj),
                        raising=False)
    cache, pipeline = BindGroupCache(), object()
    made = []

    def create():
        made.append(object())
        return made[-1]

    old = _FakeBuffer()
    first = cache.get(pipeline, 0, [(0, old, 0, 16)], create)
    assert cache.get(pipeline, 0, [(0, old, 0, 16)], create) is first and len(made) == 1
    del old
    cache._dead.clear()   # as if the freed buffer's callback had not been seen yet
    new = _FakeBuffer()   # the same "id" as the dead buffer
    second = cache.get(pipeline, 0, [(0, new, 0, 16)], create)
    assert second is not first and len(made) == 2
    assert cache.get(pipeline, 0, [(0, new, 0, 16)], create) is second and len(cache) == 1


def test_buffer_freed_while_the_cache_holds_its_lock_does_not_deadlock():
    """A buffer can die inside a lookup (garbage collection on the same thread): its callback must not
    wait for the lock; the next lookup drops its entry."""
    import threading

    from gma.gpu.bind_groups import BindGroupCache

    cache, pipeline = BindGroupCache(), object()
    holder = [_FakeBuffer()]
    cache.get(pipeline, 0, [(0, holder[0], 0, 16)], object)

    def busy_then_free():
        with cache._lock:
            holder.clear()   # the buffer's weakref callback runs now, on this thread

    worker = threading.Thread(target=busy_then_free, daemon=True)
    worker.start()
    worker.join(10)
    assert not worker.is_alive(), "the callback waited for the lock its own thread held"
    assert len(cache) == 0


TEXEL_SUM = """
@group(0) @binding(0) var src: texture_storage_2d<rgba32float, read>;
@group(0) @binding(1) var<storage, read_write> dst: array<f32>;
@compute @workgroup_size(4)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = textureLoad(src, vec2<u32>(gid.x, 0u));
    dst[gid.x] = t.x + t.y + t.z + t.w;
}
"""


def test_texture_views_reuse_bind_groups_and_never_a_dead_views(gpu):
    """A texture view kept alive (the rasterizer's texel copies keep one per texture) finds its bind group
    again; views made anew, with a dead one's id, get fresh ones that bind the new texture."""
    import wgpu

    module = gpu.device.create_shader_module(code=TEXEL_SUM)
    pipeline = gpu.device.create_compute_pipeline(layout="auto", compute={"module": module, "entry_point": "main"})
    dst = gpu.buffer(16, "dst")

    def texel_sums(view):
        bind = _dispatch(gpu, pipeline, [view, dst], 1)
        return bind, gpu.read(dst, np.float32, 4)

    for k in range(6):
        tex = gpu.device.create_texture(size=(4, 1, 1), format=wgpu.TextureFormat.rgba32float,
                                        usage=wgpu.TextureUsage.STORAGE_BINDING | wgpu.TextureUsage.COPY_DST)
        gpu.device.queue.write_texture({"texture": tex}, np.full((4, 4), float(k), np.float32).tobytes(),
                                       {"bytes_per_row": 64}, (4, 1, 1))
        view = tex.create_view()
        hits = gpu.bind_groups.hits
        first, out = texel_sums(view)
        again, out_again = texel_sums(view)
        assert again is first and gpu.bind_groups.hits == hits + 1
        np.testing.assert_array_equal(out, np.full(4, 4.0 * k))
        np.testing.assert_array_equal(out_again, out)
        del tex, view, first, again
        gc.collect()
