"""Uploads in place on CPU adapters (gma/gpu/mapped_writes.py): arrays written through the mapping of the
buffer the passes read, which is mapped again as soon as it comes back; a reused buffer is never written
while queued work still reads it."""

import gc
import time

import numpy as np
import pytest
import wgpu

from gma.gpu import GpuContext


@pytest.fixture(scope="module")
def in_place(gpu):
    if not gpu.reads_in_place:
        pytest.skip("the adapter cannot map storage buffers (a GPU, or mappable-primary-buffers missing)")
    return gpu


def _copy_out(ctx, binding) -> wgpu.GPUBuffer:
    """Encode and submit a copy of a (buffer, offset, size) range into a fresh buffer."""
    buffer, offset, size = binding
    out = ctx.buffer(size, "copied")
    enc = ctx.device.create_command_encoder()
    enc.copy_buffer_to_buffer(buffer, offset, out, 0, size)
    ctx.submit(enc)
    return out


def test_uploaded_ranges_hold_the_arrays_at_aligned_offsets(in_place):
    rng = np.random.default_rng(0)
    arrays = [rng.normal(size=(37, 3)).astype(np.float32), rng.normal(size=5).astype(np.float32),
              np.zeros(0, np.float32), rng.integers(0, 9, size=(8, 4)).astype(np.uint32)]
    packed = in_place.upload_in_place(arrays, "test.upload")
    try:
        offsets = [offset for _, offset, _ in packed.bindings]
        assert all(o % in_place.storage_alignment == 0 for o in offsets) and offsets == sorted(set(offsets))
        for a, binding in zip(arrays, packed.bindings):
            if a.nbytes:
                got = in_place.read(_copy_out(in_place, (binding[0], binding[1], a.nbytes)), a.dtype)
                np.testing.assert_array_equal(got, a.reshape(-1))
    finally:
        in_place.mapped_writes.give_back(packed.buffer)


def test_a_reused_buffer_waits_for_the_work_queued_on_it(in_place):
    writes = in_place.mapped_writes
    first = np.arange(1 << 18, dtype=np.float32)
    packed = in_place.upload_in_place([first], "test.reuse")
    copied_first = _copy_out(in_place, packed.bindings[0])   # queued, maybe not run yet
    writes.give_back(packed.buffer)
    before = writes.reused
    again = in_place.upload_in_place([-first], "test.reuse")
    assert again.buffer is packed.buffer and writes.reused == before + 1
    copied_again = _copy_out(in_place, again.bindings[0])
    np.testing.assert_array_equal(in_place.read(copied_first, np.float32), first)
    np.testing.assert_array_equal(in_place.read(copied_again, np.float32), -first)
    writes.give_back(again.buffer)


def test_a_buffer_comes_back_with_its_owner_and_is_mapped_ahead(in_place):
    writes = in_place.mapped_writes

    class Owner:
        pass

    owner = Owner()
    packed = in_place.upload_in_place([np.ones(3000, np.float32)], "test.owner")
    writes.release_with(owner, packed.buffer)
    del owner
    gc.collect()
    writes.prepare()   # as a render call does once its reads are done
    deadline = time.monotonic() + 5
    while packed.buffer not in writes.mapped_ahead() and time.monotonic() < deadline:
        time.sleep(0.001)   # wgpu's poll thread resolves the mapping
    waited = writes.waited
    again = in_place.upload_in_place([np.full(3000, 2.0, np.float32)], "test.owner")
    assert again.buffer is packed.buffer and writes.waited == waited, "mapped before it was taken"
    np.testing.assert_array_equal(in_place.read(_copy_out(in_place, again.bindings[0]), np.float32), 2.0)
    writes.give_back(again.buffer)


def test_fresh_buffers_when_recycling_is_off(in_place, monkeypatch):
    packed = in_place.upload_in_place([np.ones(64, np.float32)], "test.fresh")
    in_place.mapped_writes.give_back(packed.buffer)
    monkeypatch.setattr(in_place.recycler, "enabled", False)   # as GMA_RECYCLE=0
    fresh = in_place.upload_in_place([np.ones(64, np.float32)], "test.fresh")
    assert fresh.buffer is not packed.buffer
    in_place.mapped_writes.give_back(fresh.buffer)


def test_no_upload_in_place_without_mappable_storage_or_over_one_binding(in_place, monkeypatch):
    staging = GpuContext.create(disable_features=("mappable-primary-buffers",))
    assert staging.upload_in_place([np.ones(4, np.float32)], "test.none") is None
    monkeypatch.setattr(type(in_place), "max_binding_bytes", property(lambda self: 1024))
    assert in_place.upload_in_place([np.ones(200, np.float32), np.ones(200, np.float32)], "test.big") is None
