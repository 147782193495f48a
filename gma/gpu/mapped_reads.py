"""Read-backs without a copy on CPU adapters: outputs written in place into mappable buffers, and host
arrays that are the mapping itself until they are collected.

A read-back through a staging buffer copies twice: the driver copies the output buffer into the staging
buffer (on lavapipe's one queue thread, after the last pass), and the host copies the mapping out into
arrays that outlive it; for the public render's images and gradients both copies lie on the critical path
of every step. With wgpu's ``mappable-primary-buffers`` feature (native, requested on CPU adapters only,
where every buffer is host memory anyway) a storage buffer may also be mapped: the passes write their
outputs into ranges of one such buffer (one map per read, since each map has a fixed cost), and the
arrays returned are views of its mapping.

A buffer stays mapped, and out of the GPU's reach, while any array made from it lives: each read is a
lease, a ctypes array over the mapped range from which the arrays are made (numpy's base chain and
``torch.from_numpy`` keep it alive), whose finalizer hands the buffer back; :meth:`MappedReads.take`
unmaps the buffers handed back since the last call and reuses them. The finalizer may run during garbage
collection on any thread: it only appends to a list.
"""

from __future__ import annotations

import ctypes
import threading
from dataclasses import dataclass

import numpy as np
import wgpu

from gma.gpu.host_memory import leased_array

USAGE = wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.MAP_READ | wgpu.BufferUsage.COPY_DST
GRANULE = 64 << 10   # buffer sizes are rounded up to this, so that nearby sizes share buffers
KEEP_BUFFERS = 8     # free buffers kept for reuse at most (a training step holds two or three)


class MappedReads:
    def __init__(self, device: wgpu.GPUDevice, keep: int = KEEP_BUFFERS):
        self.device = device
        self.keep = keep
        self._free: list[wgpu.GPUBuffer] = []
        self._returned: list[wgpu.GPUBuffer] = []   # appended by finalizers, unmapped by take()
        self._lock = threading.Lock()
        self.reused = 0   # tests read it

    def take(self, nbytes: int, label: str, reuse: bool = True) -> wgpu.GPUBuffer:
        """An unmapped buffer of at least ``nbytes`` for passes to write and :meth:`read` to return (its
        contents undefined); ``reuse=False`` makes a fresh one (as a recycler switched off does)."""
        size = max(GRANULE, -(-int(nbytes) // GRANULE) * GRANULE)
        with self._lock:
            self._file_returned()
            for i in range(len(self._free) - 1, -1, -1) if reuse else ():   # the most recently returned first
                if self._free[i].size == size:
                    self.reused += 1
                    return self._free.pop(i)
        return self.device.create_buffer(label=label, size=size, usage=USAGE)

    def read(self, buffer: wgpu.GPUBuffer, nbytes: int) -> np.ndarray:
        """Wait for the work queued on ``buffer`` and return its first ``nbytes`` as a uint8 array that
        is the mapping itself; the buffer comes back to :meth:`take` once no array made from it lives."""
        nbytes = int(nbytes)
        buffer.map_sync(wgpu.MapMode.READ, 0, buffer.size)
        view = np.frombuffer(buffer.read_mapped(0, buffer.size, copy=False), np.uint8)
        address = view.ctypes.data
        del view   # wgpu releases its memoryview at unmap; the lease below does not depend on it
        return leased_array((ctypes.c_uint8 * max(nbytes, 1)).from_address(address), nbytes, self._returned.append,
                            buffer)

    def take_packed(self, sizes: list[int], label: str, reuse: bool = True) -> PackedBuffer:
        """One buffer (:meth:`take`) holding ranges of ``sizes`` bytes at the device's storage-binding
        offset alignment, for passes to write through :attr:`PackedBuffer.bindings`."""
        alignment = int(self.device.limits.get("min-storage-buffer-offset-alignment", 256))
        ranges, total = packed_ranges(sizes, alignment)
        return PackedBuffer(self.take(total, label, reuse), ranges, total)

    def read_packed(self, packed: PackedBuffer) -> list[np.ndarray]:
        """:meth:`read` of a packed buffer: one uint8 array per range, over one mapping."""
        raw = self.read(packed.buffer, packed.nbytes)
        return [raw[off:off + size] for off, size in packed.ranges]

    def _file_returned(self) -> None:
        """Unmap the buffers handed back since the last call; keep the ``keep`` most recently returned
        (lock held)."""
        while self._returned:
            buf = self._returned.pop(0)
            buf.unmap()
            self._free.append(buf)
        while len(self._free) > self.keep:
            self._free.pop(0).destroy()


@dataclass
class PackedBuffer:
    """A buffer of :meth:`MappedReads.take_packed` and its ranges ((offset, size) each)."""

    buffer: wgpu.GPUBuffer
    ranges: list[tuple[int, int]]
    nbytes: int   # up to the end of the last range's alignment

    @property
    def bindings(self) -> list[tuple[wgpu.GPUBuffer, int, int]]:
        """(buffer, offset, size) of each range, as GpuContext.bind_group binds a range."""
        return [(self.buffer, off, size) for off, size in self.ranges]


def packed_ranges(sizes: list[int], alignment: int) -> tuple[list[tuple[int, int]], int]:
    """(offset, size) of each of ``sizes`` laid out one after another at ``alignment``, and the total."""
    ranges, offset = [], 0
    for size in sizes:
        ranges.append((offset, int(size)))
        offset += -(-max(int(size), 4) // alignment) * alignment
    return ranges, max(offset, alignment)
