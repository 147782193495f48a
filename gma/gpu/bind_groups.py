"""Bind groups made once and reused while their buffers live.

Creating a bind group costs wgpu-native ~0.15 ms of validation and Python struct building; the public
``rasterize`` call made ~29 per forward+backward step (standard scene, lavapipe: ~4 ms of a ~180 ms step).
With recycled buffers (gma/gpu/recycle.py) a steady loop binds the same buffers to the same pipelines
step after step, so a bind group is looked up by (pipeline, group, every binding's buffer, offset and
size) instead of being made again.

An entry must never outlive one of its buffers: Python may give a dead buffer's ``id`` to a new one, and
the entry would bind the old buffer. Each buffer carries a weak reference whose callback, run while the
buffer is being freed (before its id can be reused), drops every entry that binds it; the entry's bind
group then releases the native buffer it still held. Entries also hold their pipeline, so its id stays
unique, and the least recently used go first beyond ``limit``.
"""

from __future__ import annotations

import threading
import weakref
from collections import OrderedDict

import wgpu

BIND_GROUP_CACHE_ENTRIES = 512


class BindGroupCache:
    def __init__(self, limit: int = BIND_GROUP_CACHE_ENTRIES):
        self.limit = limit
        self._entries: OrderedDict[tuple, tuple[wgpu.GPUBindGroup, object]] = OrderedDict()
        self._keys_by_buffer: dict[int, set[tuple]] = {}   # id(buffer) -> keys of the entries binding it
        self._buffer_refs: dict[int, weakref.ref] = {}      # id(buffer) -> its weak reference (with callback)
        self._lock = threading.Lock()  # callbacks may run on any thread
        self.hits = 0  # tests and benchmarks read it

    def get(self, pipeline, group: int, bindings: list[tuple[int, wgpu.GPUBuffer, int, int]], create):
        """The bind group of ``bindings`` (binding, buffer, offset, size) for ``pipeline``'s group, made
        by ``create()`` the first time."""
        key = (id(pipeline), group, tuple((i, id(buf), off, size) for i, buf, off, size in bindings))
        with self._lock:
            entry = self._entries.get(key)
            if entry is not None:
                self._entries.move_to_end(key)
                self.hits += 1
                return entry[0]
        bind_group = create()
        with self._lock:
            self._entries[key] = (bind_group, pipeline)
            for _, buf, _, _ in bindings:
                ident = id(buf)
                if ident not in self._buffer_refs:
                    self._buffer_refs[ident] = weakref.ref(buf, self._buffer_freed_callback(ident))
                self._keys_by_buffer.setdefault(ident, set()).add(key)
            while len(self._entries) > self.limit:
                old_key, _ = self._entries.popitem(last=False)
                self._forget_key(old_key)
        return bind_group

    def __len__(self) -> int:
        return len(self._entries)

    def _buffer_freed_callback(self, ident: int):
        def freed(_ref):
            with self._lock:
                self._buffer_refs.pop(ident, None)
                for key in self._keys_by_buffer.pop(ident, ()):
                    if self._entries.pop(key, None) is not None:
                        self._forget_key(key, except_buffer=ident)
        return freed

    def _forget_key(self, key: tuple, except_buffer: int | None = None) -> None:
        """Unlist a dropped entry under its other buffers (called with the lock held)."""
        for _, ident, _, _ in key[2]:
            if ident == except_buffer:
                continue
            keys = self._keys_by_buffer.get(ident)
            if keys is not None:
                keys.discard(key)
