"""Bind groups made once and reused while their buffers (and texture views) live.

Creating a bind group costs wgpu-native validation and Python struct building, and the public
``rasterize`` call binds a few dozen groups per forward+backward step.
With recycled buffers (gma/gpu/recycle.py) a steady loop binds the same buffers to the same pipelines
step after step, so a bind group is looked up by (pipeline, group, every binding's buffer, offset and
size) instead of being made again. A texture view is keyed like a buffer (offset and size 0): the
rasterizer keeps one view per texel texture (gma/render/surfel_texels.py).

An entry must never serve a buffer it was not made with: Python may give a dead buffer's ``id`` to a new
one. So an entry keeps weak references to its buffers and a lookup checks that each still refers to the
very buffer asked for. A buffer's death is also noted by its weak reference's callback, and the next
lookup drops that buffer's entries, so that their bind groups release the native buffers they hold. The
callback only appends to a list: it may run inside garbage collection, even on a thread that is in the
middle of a lookup, so it must not wait for the lock. Entries hold their pipeline (its id stays unique),
and the least recently used go first beyond ``limit``.
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
        # key -> (bind group, pipeline, weak references to the bound buffers)
        self._entries: OrderedDict[tuple, tuple[wgpu.GPUBindGroup, object, tuple]] = OrderedDict()
        self._keys_by_buffer: dict[int, set[tuple]] = {}   # id(buffer) -> keys of the entries binding it
        self._buffer_refs: dict[int, weakref.ref] = {}      # id(buffer) -> its weak reference (with callback)
        self._dead: list[int] = []                           # ids of buffers freed since the last purge
        self._lock = threading.Lock()
        self.hits = 0  # tests and benchmarks read it

    def get(self, pipeline, group: int, bindings: list[tuple[int, wgpu.GPUBuffer, int, int]], create):
        """The bind group of ``bindings`` (binding, buffer, offset, size) for ``pipeline``'s group, made
        by ``create()`` the first time."""
        key = (id(pipeline), group, tuple((i, id(buf), off, size) for i, buf, off, size in bindings))
        with self._lock:
            self._purge()
            entry = self._entries.get(key)
            if entry is not None:
                if entry[1] is pipeline and all(ref() is buf for ref, (_, buf, _, _) in zip(entry[2], bindings)):
                    self._entries.move_to_end(key)
                    self.hits += 1
                    return entry[0]
                self._drop(key)   # made for a buffer or pipeline that has died since (ids are reused)
        bind_group = create()
        with self._lock:
            refs = []
            for _, buf, _, _ in bindings:
                ident = id(buf)
                ref = self._buffer_refs.get(ident)
                if ref is None or ref() is not buf:
                    ref = self._buffer_refs[ident] = weakref.ref(buf, self._dead_callback(ident))
                refs.append(ref)
                self._keys_by_buffer.setdefault(ident, set()).add(key)
            self._entries[key] = (bind_group, pipeline, tuple(refs))
            while len(self._entries) > self.limit:
                self._drop(next(iter(self._entries)))
        return bind_group

    def __len__(self) -> int:
        with self._lock:
            self._purge()
            return len(self._entries)

    def _dead_callback(self, ident: int):
        dead = self._dead
        return lambda _ref: dead.append(ident)   # list.append: atomic, takes no lock

    def _purge(self) -> None:
        """Drop the entries of buffers that died (called with the lock held)."""
        while self._dead:
            ident = self._dead.pop()
            ref = self._buffer_refs.get(ident)
            if ref is not None and ref() is None:
                del self._buffer_refs[ident]
            # The id may already belong to a newer, live buffer: drop only entries with a dead buffer.
            for key in list(self._keys_by_buffer.get(ident, ())):
                if any(r() is None for r in self._entries[key][2]):
                    self._drop(key)

    def _drop(self, key: tuple) -> None:
        """Remove an entry and unlist it under its buffers (called with the lock held)."""
        if self._entries.pop(key, None) is None:
            return
        for _, ident, _, _ in key[2]:
            keys = self._keys_by_buffer.get(ident)
            if keys is not None:
                keys.discard(key)
                if not keys:
                    del self._keys_by_buffer[ident]
