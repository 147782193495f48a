"""Exclusive prefix sum of u32 on the GPU (block scans, recursively scanned block sums, add-back)."""

from __future__ import annotations

import numpy as np
import wgpu

from gma.gpu import GpuContext
from gma.gpu.workspace import Workspace

SCAN_BLOCK = 1024  # mirrors shaders/wgsl/render/scan_blocks.wgsl
UNIFORM = wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST


class ExclusiveScan:
    """``out[i] = sum(values[:i])``, optionally of ``values[index[i]]`` (a gather), for a count known
    when encoding."""

    def __init__(self, ctx: GpuContext, workspace: Workspace | None = None):
        self.ctx = ctx
        self.workspace = workspace or Workspace(ctx)

    def encode(self, encoder: wgpu.GPUCommandEncoder, values: wgpu.GPUBuffer, out: wgpu.GPUBuffer,
               count: int, index: wgpu.GPUBuffer | None = None, level: int = 0, timer=None) -> None:
        """Encode the scan; with a :class:`~gma.gpu.PassTimer` its passes are timed as "scan"."""
        ctx = self.ctx
        if count == 0:
            return
        blocks = (count + SCAN_BLOCK - 1) // SCAN_BLOCK
        # Scratch per recursion level. The 16-byte uniform is a constant of the count, never rewritten: queue
        # writes land before the whole submission, so a rewritten shared one would break two scans encoded
        # into one submission.
        sums = self.workspace.get(f"scan.block_sums.{level}", 4 * blocks)
        params = ctx.constant(np.array([count, 0, 0, 0], np.uint32), "scan.params", UNIFORM)
        gather = index is not None
        blocks_p = ctx.compute_pipeline("render/scan_blocks.wgsl", {"GATHER": gather})
        bind = [params, values, index if gather else values, out, sums]
        cp = encoder.begin_compute_pass(timestamp_writes=timer.writes("scan") if timer else None)
        cp.set_pipeline(blocks_p)
        cp.set_bind_group(0, ctx.bind_group(blocks_p, bind))
        cp.dispatch_workgroups(blocks)
        cp.end()
        if blocks > 1:
            offsets = self.workspace.get(f"scan.block_offsets.{level}", 4 * blocks)
            self.encode(encoder, sums, offsets, blocks, level=level + 1, timer=timer)
            add_p = ctx.compute_pipeline("render/scan_add.wgsl")
            cp = encoder.begin_compute_pass(timestamp_writes=timer.writes("scan") if timer else None)
            cp.set_pipeline(add_p)
            cp.set_bind_group(0, ctx.bind_group(add_p, [params, offsets, out]))
            groups = (count + 255) // 256
            cp.dispatch_workgroups(min(groups, 65535), (groups + 65534) // 65535)
            cp.end()

    def scan(self, values: np.ndarray, index: np.ndarray | None = None) -> np.ndarray:
        """Convenience for tests: scan a host array on the GPU."""
        ctx = self.ctx
        values = np.ascontiguousarray(values, np.uint32)
        n = values.size if index is None else index.size
        if n == 0:
            return np.zeros(0, np.uint32)
        vb = ctx.upload(values, "values")
        ib = None if index is None else ctx.upload(np.asarray(index, np.uint32), "index")
        out = ctx.buffer(4 * n, "out")
        enc = ctx.device.create_command_encoder()
        self.encode(enc, vb, out, n, ib)
        ctx.submit(enc)
        return ctx.read(out, np.uint32, n)
