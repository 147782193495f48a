"""Uploads without a staging copy on CPU adapters: inputs written through the mapping of the storage
buffer the passes read, which is mapped again, ahead of its next use, as soon as it comes back.

``queue.write_buffer`` copies an upload into a staging buffer, and before the next pass can start
lavapipe's one queue thread copies it again into the buffer the pass reads, while the GPU's threads wait:
on the standard scene (100k surfels, 512x512) the five surfel arrays (5.2 MB) delayed projection by
~1.1 ms after the submission, the upstream image gradients (3 MB) the backward by ~0.6 ms. With wgpu's
``mappable-primary-buffers`` (requested on CPU adapters only, see gma/gpu/context.py) a storage buffer
can be mapped for writing, and the host's one copy is the upload. But a map waits for the GPU to be done
with the buffer and for wgpu's poll thread to report it (0.3-0.8 ms inside a training step, more than
the queue's copy saved), so buffers are mapped again as soon as they come back
(:meth:`MappedWrites.prepare`, at the end of each render call, when the GPU is idle), and a buffer taken
for an upload is normally mapped already. New buffers are created mapped.

Buffers come back through :meth:`MappedWrites.release_with` (when an owner is garbage-collected: the
finalizer only appends to a list, as it may run on any thread) or :meth:`MappedWrites.give_back`.
"""

from __future__ import annotations

import threading
import weakref

import numpy as np
import wgpu

from gma.gpu.mapped_reads import GRANULE, PackedBuffer, packed_ranges

USAGE = wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.MAP_WRITE | wgpu.BufferUsage.COPY_SRC
KEEP_BUFFERS = 6   # free buffers kept at most (a training step uses two and has two more coming back)


class MappedWrites:
    def __init__(self, device: wgpu.GPUDevice, keep: int = KEEP_BUFFERS):
        self.device = device
        self.keep = keep
        self._free: list[tuple[wgpu.GPUBuffer, object]] = []   # (buffer, its mapping's promise)
        self._returned: list[wgpu.GPUBuffer] = []   # appended by finalizers; prepare() maps them
        self._lock = threading.Lock()
        self.reused = 0   # tests read them
        self.created = 0
        self.waited = 0   # reused buffers whose mapping had not resolved when taken

    def upload(self, arrays: list[np.ndarray], alignment: int, label: str, reuse: bool = True) -> PackedBuffer:
        """``arrays`` (C-contiguous) written into ranges of one buffer at ``alignment``, unmapped and ready
        for passes to read through :attr:`PackedBuffer.bindings`; ``reuse=False`` makes a fresh buffer (as
        the recycler's switch, GMA_RECYCLE=0). The caller gives the buffer back."""
        ranges, total = packed_ranges([max(a.nbytes, 16) for a in arrays], alignment)
        buffer = self._take(total, label, reuse)
        try:
            for a, (offset, _) in zip(arrays, ranges):
                if a.nbytes:
                    buffer.write_mapped(a.reshape(-1).view(np.uint8), offset)
        finally:
            buffer.unmap()
        return PackedBuffer(buffer, ranges, total)

    def release_with(self, owner, buffer: wgpu.GPUBuffer) -> None:
        """Take ``buffer`` back once ``owner`` is garbage-collected (mapped again by the next
        :meth:`prepare`). Nothing else may hold it then."""
        done = weakref.finalize(owner, self._returned.append, buffer)
        done.atexit = False

    def give_back(self, buffer: wgpu.GPUBuffer) -> None:
        """Take ``buffer`` back now and start mapping it (queued work on it may still run)."""
        self._returned.append(buffer)
        self.prepare()

    def prepare(self) -> None:
        """Start mapping the buffers that came back (each map resolves once the GPU is done with its
        buffer), keeping the ``keep`` most recently returned."""
        with self._lock:
            while self._returned:
                buffer = self._returned.pop(0)
                self._free.append((buffer, buffer.map_async(wgpu.MapMode.WRITE, 0, buffer.size)))
            while len(self._free) > self.keep:
                self._free.pop(0)[0].destroy()

    def mapped_ahead(self) -> list[wgpu.GPUBuffer]:
        """The free buffers whose mapping has resolved: an upload takes them without waiting."""
        with self._lock:
            return [buffer for buffer, mapping in self._free if _resolved(mapping)]

    def _take(self, nbytes: int, label: str, reuse: bool) -> wgpu.GPUBuffer:
        """A buffer of at least ``nbytes``, mapped for writing (contents undefined)."""
        size = max(GRANULE, -(-int(nbytes) // GRANULE) * GRANULE)
        self.prepare()
        taken = None
        with self._lock:
            matching = [i for i, (b, _) in enumerate(self._free) if b.size == size] if reuse else []
            if matching:
                # The most recently returned one whose mapping is done, else the most recent (and wait).
                ready = [i for i in matching if _resolved(self._free[i][1])]
                taken = self._free.pop((ready or matching)[-1])
                self.reused += 1
        if taken is None:
            self.created += 1
            return self.device.create_buffer(label=label, size=size, usage=USAGE, mapped_at_creation=True)
        buffer, mapping = taken
        if not _resolved(mapping):
            self.waited += 1
        mapping.sync_wait()   # (the buffer's map state changes here, when the promise is resolved)
        return buffer


def _resolved(mapping) -> bool:
    """Whether a mapping's promise has its result (wgpu-py sets the buffer's map state only when the
    promise is awaited; its state attribute says whether the callback came)."""
    return getattr(mapping, "_state", "pending") != "pending"
