"""Grow-only scratch buffers reused from frame to frame, so a steady frame allocates nothing.

Only for buffers whose contents do not outlive the submission that uses them (sort scratch, scan
partials, per-frame intersection lists of the viewer path). A reused buffer holds stale data: passes
that rely on zeros must clear it (``encoder.clear_buffer``).
"""

from __future__ import annotations

import wgpu

from gma.gpu.context import STORAGE, GpuContext


class Workspace:
    def __init__(self, ctx: GpuContext):
        self.ctx = ctx
        self._buffers: dict[str, wgpu.GPUBuffer] = {}

    def get(self, label: str, nbytes: int, usage: int = STORAGE) -> wgpu.GPUBuffer:
        """A buffer of at least ``nbytes`` for ``label``; grows by 25% steps to avoid churn."""
        nbytes = max(4, (int(nbytes) + 3) // 4 * 4)
        buf = self._buffers.get(label)
        if buf is None or buf.size < nbytes or buf.usage != usage:
            size = nbytes if buf is None else max(nbytes, int(buf.size * 1.25) // 4 * 4)
            buf = self._buffers[label] = self.ctx.buffer(size, label, usage)
        return buf

    @property
    def nbytes(self) -> int:
        return sum(b.size for b in self._buffers.values())
