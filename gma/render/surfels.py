"""Surfels that live in GPU buffers: the renderer's inputs, in the layout posing passes write to."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import wgpu

from gma.gpu import GpuContext
from gma.gpu.context import STORAGE

Binding = wgpu.GPUBuffer | tuple[wgpu.GPUBuffer, int, int]   # as GpuContext.bind_group binds them


@dataclass
class SurfelBuffers:
    """Packed float32 storage buffers (no vec3 padding): ``means`` [N, 3], ``quats`` [N, 4] (w, x, y, z),
    ``scales`` [N, 2] (activated, > 0), ``opacities`` [N] (activated), ``colors`` [N, C]. Each a buffer, or
    a (buffer, offset, size) range of one (see from_arrays)."""

    means: Binding
    quats: Binding
    scales: Binding
    opacities: Binding
    colors: Binding
    count: int
    channels: int

    @staticmethod
    def allocate(ctx: GpuContext, count: int, channels: int = 3, recycled: bool = False) -> SurfelBuffers:
        """Buffers for ``count`` surfels. ``recycled``: from the context's recycler, given back when the
        object is garbage-collected (stale contents: for callers that write them all, as from_arrays does)."""
        n = max(count, 1)
        def make(nbytes: int, label: str) -> wgpu.GPUBuffer:
            return ctx.recycler.take(nbytes, label, STORAGE) if recycled else ctx.buffer(nbytes, label)

        bufs = SurfelBuffers(
            means=make(12 * n, "surfels.means"),
            quats=make(16 * n, "surfels.quats"),
            scales=make(8 * n, "surfels.scales"),
            opacities=make(4 * n, "surfels.opacities"),
            colors=make(4 * channels * n, "surfels.colors"),
            count=count,
            channels=channels,
        )
        if recycled:
            ctx.recycler.release_with(bufs, [bufs.means, bufs.quats, bufs.scales, bufs.opacities, bufs.colors])
        return bufs

    @staticmethod
    def from_arrays(ctx: GpuContext, means, quats, scales, opacities, colors, recycled: bool = False) -> SurfelBuffers:
        """Upload host arrays (numpy or CPU torch tensors) of the shapes above (``recycled``: see allocate).
        Recycled uploads on CPU adapters go straight into ranges of one mapped buffer
        (``GpuContext.upload_in_place``), and the fields are then (buffer, offset, size) ranges: bind them,
        do not write them."""
        colors = np.asarray(colors, np.float32)
        if recycled:
            arrays = [np.asarray(a, np.float32) for a in (means, quats, scales, opacities)] + [colors]
            packed = ctx.upload_in_place(arrays, "surfels.packed")
            if packed is not None:
                bufs = SurfelBuffers(*packed.bindings, count=len(colors), channels=colors.shape[1])
                ctx.mapped_writes.release_with(bufs, packed.buffer)
                return bufs
        bufs = SurfelBuffers.allocate(ctx, len(colors), colors.shape[1], recycled)
        bufs.write(ctx, means, quats, scales, opacities, colors)
        return bufs

    def write(self, ctx: GpuContext, means, quats, scales, opacities, colors) -> None:
        """Overwrite the contents (same N and C) without reallocating."""
        for buf, arr in ((self.means, means), (self.quats, quats), (self.scales, scales),
                         (self.opacities, opacities), (self.colors, colors)):
            ctx.write(buf, np.asarray(arr, np.float32))
