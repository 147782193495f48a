"""Recycled buffers for objects that live for one call or one training step (a differentiable render's
kept state, its uploaded surfels, its gradients), so that a loop of renders stops allocating.

A fresh multi-megabyte buffer is expensive on a CPU adapter: lavapipe maps new memory, every page faults
on first touch, and wgpu zero-fills whatever a pass reads before anything wrote it; the public
``gma.render.rasterize`` call needs tens of megabytes of such buffers per forward+backward step of a large
scene (docs/design.md says what recycling saves).

The owner's buffers come back when the owner is garbage-collected (:meth:`BufferRecycler.release_with`),
and a later ``take`` of the same size and usage hands them out again. WebGPU runs submissions in order,
so work already queued on a released buffer finishes before a later submission writes it. A recycled
buffer holds stale data: only buffers that the GPU fully writes before it reads them may come from here
(zero-filled ones, such as accumulators, must be made with ``GpuContext.buffer``).
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict

import wgpu

RECYCLE_KEEP_BYTES = 256 << 20  # released buffers kept for reuse, at most (the oldest go first)


class BufferRecycler:
    def __init__(self, ctx, keep_bytes: int = RECYCLE_KEEP_BYTES, enabled: bool = True):
        self.ctx = ctx
        self.keep_bytes = keep_bytes
        self._free: OrderedDict[int, tuple[tuple[int, int], wgpu.GPUBuffer]] = OrderedDict()  # by id, oldest first
        self._free_bytes = 0
        self._lock = threading.Lock()
        # Buffers of owners that were garbage-collected, not yet listed as free. A finalizer may run inside
        # garbage collection on a thread that holds the lock (in take), so it only appends here
        # (list.append takes no lock) and the next call under the lock lists them.
        self._released: list[tuple[wgpu.GPUBuffer, ...]] = []
        self.reused = 0  # buffers handed out again (tests and benchmarks read it)
        # Off: every take allocates (tests compare against fresh, zero-filled buffers).
        self.enabled = enabled

    def take(self, nbytes: int, label: str, usage: int) -> wgpu.GPUBuffer:
        """A released buffer of exactly this (rounded) size and usage, stale contents and all, or a new one
        (``GpuContext.buffer``, which also enforces the adapter's limits)."""
        size = max(4, (int(nbytes) + 3) // 4 * 4)
        key = (size, int(usage))
        with self._lock:
            self._list_released()
            if self.enabled:
                for ident in reversed(self._free):   # the most recently released first: likeliest in the caches
                    k, buf = self._free[ident]
                    if k == key:
                        del self._free[ident]
                        self._free_bytes -= size
                        self.reused += 1
                        return buf
        return self.ctx.buffer(size, label, usage)

    def release_with(self, owner, buffers) -> None:
        """Give ``buffers`` back once ``owner`` is garbage-collected. Nothing else may hold them then."""
        done = weakref.finalize(owner, self._released.append, tuple(b for b in buffers if b is not None))
        done.atexit = False  # nothing to give back at interpreter exit

    def give_back(self, buffers) -> None:
        """Give ``buffers`` back now (their owner is done with them; queued work on them may still run)."""
        self._give(tuple(buffers))

    def _give(self, buffers: tuple[wgpu.GPUBuffer, ...]) -> None:
        with self._lock:
            self._list_released()
            self._list_free(buffers)

    def _list_released(self) -> None:
        """List the garbage-collected owners' buffers as free, in the order they came (lock held)."""
        while self._released:
            self._list_free(self._released.pop(0))

    def _list_free(self, buffers: tuple[wgpu.GPUBuffer, ...]) -> None:
        """(lock held)"""
        if self.enabled:
            for buf in buffers:
                if id(buf) in self._free:  # listed twice: keep one entry
                    continue
                self._free[id(buf)] = ((int(buf.size), int(buf.usage)), buf)
                self._free_bytes += int(buf.size)
            while self._free_bytes > self.keep_bytes and self._free:
                _, ((size, _), _) = self._free.popitem(last=False)
                self._free_bytes -= size

    @property
    def free_bytes(self) -> int:
        with self._lock:
            self._list_released()
            return self._free_bytes
