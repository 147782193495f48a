"""Surfels that live in GPU buffers: the renderer's inputs, in the layout posing passes write to."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import wgpu

from gma.gpu import GpuContext
from gma.gpu.context import STORAGE


@dataclass
class SurfelBuffers:
    """Packed float32 storage buffers (no vec3 padding): ``means`` [N, 3], ``quats`` [N, 4] (w, x, y, z),
    ``scales`` [N, 2] (activated, > 0), ``opacities`` [N] (activated), ``colors`` [N, C]."""

    means: wgpu.GPUBuffer
    quats: wgpu.GPUBuffer
    scales: wgpu.GPUBuffer
    opacities: wgpu.GPUBuffer
    colors: wgpu.GPUBuffer
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
        """Upload host arrays (numpy or CPU torch tensors) of the shapes above (``recycled``: see allocate)."""
        colors = np.asarray(colors, np.float32)
        bufs = SurfelBuffers.allocate(ctx, len(colors), colors.shape[1], recycled)
        bufs.write(ctx, means, quats, scales, opacities, colors)
        return bufs

    def write(self, ctx: GpuContext, means, quats, scales, opacities, colors) -> None:
        """Overwrite the contents (same N and C) without reallocating."""
        for buf, arr in ((self.means, means), (self.quats, quats), (self.scales, scales),
                         (self.opacities, opacities), (self.colors, colors)):
            ctx.write(buf, np.asarray(arr, np.float32))
