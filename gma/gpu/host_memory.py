"""Host memory for read-backs, reused once the arrays made from it are gone.

Every read-back needs fresh host memory: the arrays become the caller's tensors (images, gradients) and
live on after the call. Fresh memory costs a page fault at the first touch of every 4 KB page, which
makes a copy of megabytes of images into fresh pages many times slower than into pages touched before
(docs/design.md). A training loop
drops the previous step's outputs before or while it makes the next ones, so the same few regions serve
every step once their arrays are collected.

A region is an anonymous memory mapping kept by the pool; each use of it is a :class:`_Lease`, a ctypes
array over the region's memory from which the returned numpy array is made. Every view of that array
keeps the lease alive (numpy's base chain, and ``torch.from_numpy`` holds the array), so the lease's
finalizer runs only once nothing can read the memory any more, and only then is the region free again.
The finalizer may run during garbage collection on any thread: it only appends to a list.
"""

from __future__ import annotations

import ctypes
import mmap
import threading
import weakref

import numpy as np

PAGE = mmap.PAGESIZE
# Free regions kept for reuse at most (beyond that they are unmapped): a 512 x 512 training step reads back
# ~14 MB; much larger reads (a 4K frame's images) are simply not kept.
KEEP_BYTES = 128 << 20


class HostMemoryPool:
    def __init__(self, keep_bytes: int = KEEP_BYTES):
        self.keep_bytes = keep_bytes
        self._free: dict[int, list[mmap.mmap]] = {}   # region size -> free regions
        self._free_bytes = 0
        self._returned: list[mmap.mmap] = []           # appended by finalizers, filed by take()
        self._lock = threading.Lock()
        self.reused = 0   # tests and benchmarks read it

    def take(self, nbytes: int) -> np.ndarray:
        """``nbytes`` of host memory as a writable uint8 array, its contents undefined (a reused region
        holds an earlier read's bytes). Given back to the pool when the array and all its views are gone."""
        nbytes = int(nbytes)
        size = max(PAGE, -(-nbytes // PAGE) * PAGE)
        with self._lock:
            self._file_returned()
            regions = self._free.get(size)
            region = regions.pop() if regions else None
            if region is not None:
                self._free_bytes -= size
                self.reused += 1
        if region is None:
            region = mmap.mmap(-1, size)
        # The ctypes array holds an export of the region's buffer while it lives; the finalizer gets the
        # region itself (not the lease, which is gone by then).
        return leased_array((ctypes.c_uint8 * max(nbytes, 1)).from_buffer(region), nbytes, self._returned.append,
                            region)

    def _file_returned(self) -> None:
        """Move regions given back since the last call into the free lists (called with the lock held)."""
        while self._returned:
            region = self._returned.pop()
            size = len(region)
            if self._free_bytes + size > self.keep_bytes:
                continue   # dropped: unmapped when its last reference goes
            self._free.setdefault(size, []).append(region)
            self._free_bytes += size

    @property
    def free_bytes(self) -> int:
        with self._lock:
            self._file_returned()
            return self._free_bytes


def leased_array(lease: ctypes.Array, nbytes: int, give_back, item) -> np.ndarray:
    """The first ``nbytes`` of the ctypes array ``lease`` as a uint8 numpy array; once it and every view
    of it (torch tensors from it included) are gone, ``give_back(item)`` runs, possibly inside garbage
    collection on any thread, so it must only file ``item`` (list.append)."""
    weakref.finalize(lease, give_back, item).atexit = False
    return np.frombuffer(lease, np.uint8)[:nbytes]
