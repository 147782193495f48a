"""Surfels that live in GPU buffers: the renderer's inputs, in the layout posing passes write to."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import wgpu

from gma.gpu import GpuContext


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
    def allocate(ctx: GpuContext, count: int, channels: int = 3) -> SurfelBuffers:
        n = max(count, 1)
        return SurfelBuffers(
            means=ctx.buffer(12 * n, "surfels.means"),
            quats=ctx.buffer(16 * n, "surfels.quats"),
            scales=ctx.buffer(8 * n, "surfels.scales"),
            opacities=ctx.buffer(4 * n, "surfels.opacities"),
            colors=ctx.buffer(4 * channels * n, "surfels.colors"),
            count=count,
            channels=channels,
        )

    @staticmethod
    def from_arrays(ctx: GpuContext, means, quats, scales, opacities, colors) -> SurfelBuffers:
        """Upload host arrays (numpy or CPU torch tensors) of the shapes above."""
        colors = np.asarray(colors, np.float32)
        bufs = SurfelBuffers.allocate(ctx, len(colors), colors.shape[1])
        bufs.write(ctx, means, quats, scales, opacities, colors)
        return bufs

    def write(self, ctx: GpuContext, means, quats, scales, opacities, colors) -> None:
        """Overwrite the contents (same N and C) without reallocating."""
        for buf, arr in ((self.means, means), (self.quats, quats), (self.scales, scales),
                         (self.opacities, opacities), (self.colors, colors)):
            ctx.write(buf, np.asarray(arr, np.float32))
