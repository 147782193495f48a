"""Stable GPU radix sort of u32 keys with u32 values: count, scan and scatter per digit, with 4-bit digits
(sort/radix_*.wgsl, any adapter) or, on lavapipe, with digits of up to 11 bits ranked by one subgroup per
block (sort/lane_*.wgsl), so that the renderer's sorts take one or two passes instead of three to six."""

from __future__ import annotations

import numpy as np
import wgpu

from gma.gpu import GpuContext
from gma.gpu.workspace import Workspace

SORT_BLOCK = 2048  # keys per workgroup; mirrors shaders/wgsl/common/sort_types.wgsl
RADIX_BITS = 4  # digit width; mirrors shaders/wgsl/sort/radix_digits.wgsl (whose counters are packed for 4 bits)
# Threads per block (SORT_WG in sort/radix_digits.wgsl, which says why): many threads with few keys each on
# GPUs, few threads with many keys each on CPU drivers. At least 1 << RADIX_BITS; at most 255 keys a thread.
GPU_SORT_THREADS = 128
CPU_SORT_THREADS = 16
# The lane-ordered variant (sort/lane_digits.wgsl): 8-lane subgroups, digits of at most 11 bits (2^11 + 1
# counters fill half of the 16 KiB of workgroup memory WebGPU guarantees; 12 would not fit), 4 sort blocks
# per workgroup (smaller histograms; still a dozen or more workgroups for 100k keys).
LANE_SORT_LANES = 8
LANE_MAX_DIGIT_BITS = 11
LANE_GROUP_BLOCKS = 4


def lane_sort_supported(ctx: GpuContext) -> bool:
    """Whether the lane-ordered variant runs correctly here: it needs a CPU driver that runs a subgroup of
    8 lanes as one SIMD thread in program order (lavapipe; sort/lane_digits.wgsl)."""
    return ctx.is_lavapipe and ctx.has_subgroups and ctx.subgroup_size == LANE_SORT_LANES


def sort_blocks(count: int) -> int:
    return max(1, (count + SORT_BLOCK - 1) // SORT_BLOCK)


def dispatch_info(count: int, per_group: int) -> np.ndarray:
    """Packed ``DispatchInfo`` for ``count`` elements at ``per_group`` elements per workgroup."""
    return np.array([max(1, (count + per_group - 1) // per_group), 1, 1, count], np.uint32)


class RadixSorter:
    """Sorts ``count`` (key, value) pairs in place on the GPU, stably, by the low ``bits`` of the key.

    The element count comes from a ``DispatchInfo`` buffer (workgroups for the count/scatter passes and
    the count itself), so it can be produced by an earlier GPU pass without a readback; the dispatches
    are then indirect. ``capacity`` bounds the count and sizes the scratch buffers.
    """

    def __init__(self, ctx: GpuContext, workspace: Workspace | None = None, threads: int | None = None,
                 lanes: bool | None = None):
        """``threads``: of the 4-bit variant's blocks (default by adapter). ``lanes``: use the lane-ordered
        variant (default: where :func:`lane_sort_supported`)."""
        self.ctx = ctx
        self.workspace = workspace or Workspace(ctx)
        supported = lane_sort_supported(ctx)
        if lanes and not supported:
            raise ValueError("the lane-ordered sort needs lavapipe with 8-lane subgroups")
        self.lanes = supported if lanes is None else lanes
        self.max_digit_bits = LANE_MAX_DIGIT_BITS   # of the lane-ordered variant (tests lower it)
        self.threads = threads or (CPU_SORT_THREADS if ctx.is_software else GPU_SORT_THREADS)
        keys_each = SORT_BLOCK // max(self.threads, 1)
        # An even number of keys each: the passes take a thread's keys two per step (radix_digits.wgsl).
        if self.threads < (1 << RADIX_BITS) or SORT_BLOCK % self.threads or keys_each > 255 or keys_each % 2:
            raise ValueError(f"{self.threads} sort threads per block: need a divisor of {SORT_BLOCK} with at "
                             f"least {1 << RADIX_BITS} threads and an even number of keys each, at most 254")

    def encode(self, encoder: wgpu.GPUCommandEncoder, info: wgpu.GPUBuffer, keys: wgpu.GPUBuffer,
               values: wgpu.GPUBuffer, capacity: int, bits: int, timer=None,
               base: tuple[wgpu.GPUBuffer, int] | None = None,
               source: tuple[wgpu.GPUBuffer, wgpu.GPUBuffer] | None = None) -> None:
        """Encode the sort; the result ends up in ``keys``/``values``. With ``base`` (a buffer and the
        index of a u32 in it) the sort orders ``key - base`` by its low ``bits`` (wrapping), for keys that
        lie within ``2**bits`` above the base. With ``source`` (keys, values) the pairs are read from there
        and ``keys``/``values`` only receive them (no copy at the end for an odd number of passes, as the
        in-place sort needs; the renderer's tile sort takes one pass on lavapipe); the source is left as is."""
        ctx = self.ctx
        extra = [base[0]] if base else []
        digit_bits, count_p, scan_p, scatter_p = self._pipelines(bits, base)
        groups = -(-sort_blocks(capacity) // self.group_blocks)   # histogram columns: one per workgroup
        hist = self.workspace.get("sort.hist", (4 << digit_bits) * groups)
        tmp = (self.workspace.get("sort.keys_tmp", 4 * capacity), self.workspace.get("sort.vals_tmp", 4 * capacity))
        passes = len(count_p)
        out = (keys, values)
        if source is None:   # in place: ping-pong with the scratch pair, copy back after an odd count
            src, targets = out, [tmp if i % 2 == 0 else out for i in range(passes)]
        else:   # the last pass writes the output, earlier ones alternate with the scratch pair before it
            src, targets = source, [out if (passes - 1 - i) % 2 == 0 else tmp for i in range(passes)]
        scan_bg = ctx.bind_group(scan_p, [info, hist])
        for i, dst in enumerate(targets):
            cp = encoder.begin_compute_pass(timestamp_writes=timer.writes("sort") if timer else None)
            cp.set_pipeline(count_p[i])
            cp.set_bind_group(0, ctx.bind_group(count_p[i], [info, src[0], hist] + extra))
            cp.dispatch_workgroups_indirect(info, 0)
            cp.set_pipeline(scan_p)
            cp.set_bind_group(0, scan_bg)
            cp.dispatch_workgroups(1)
            cp.set_pipeline(scatter_p[i])
            cp.set_bind_group(0, ctx.bind_group(scatter_p[i], [info, hist, src[0], src[1], dst[0], dst[1]] + extra))
            cp.dispatch_workgroups_indirect(info, 0)
            cp.end()
            src = dst
        if src is not out:
            # The result sits in the scratch pair: copy it back (cheaper than one more radix pass).
            encoder.copy_buffer_to_buffer(tmp[0], 0, keys, 0, 4 * capacity)
            encoder.copy_buffer_to_buffer(tmp[1], 0, values, 0, 4 * capacity)

    @property
    def group_blocks(self) -> int:
        """Sort blocks per workgroup (each with its histogram column)."""
        return LANE_GROUP_BLOCKS if self.lanes else 1

    def passes(self, bits: int) -> int:
        """Count/scan/scatter rounds of a ``bits``-bit sort."""
        return max(1, -(-bits // (self.max_digit_bits if self.lanes else RADIX_BITS)))

    def _pipelines(self, bits: int, base):
        """Digit width and the pipelines of a ``bits``-bit sort: count and scatter per pass, and the scan."""
        ctx = self.ctx
        keyed = {"KEY_BASE": True, "KEY_BASE_WORD": base[1]} if base else {}
        passes = self.passes(bits)
        if self.lanes:
            digit_bits = -(-bits // passes)   # the passes share the bits evenly: smaller histograms
            folder, defines = "sort/lane", {"DIGIT_BITS": digit_bits, "GROUP_BLOCKS": self.group_blocks, **keyed}
        else:
            digit_bits = RADIX_BITS
            folder, defines = "sort/radix", {"SORT_WG": self.threads, **keyed}
        count_p = [ctx.compute_pipeline(f"{folder}_count.wgsl", {"SHIFT": digit_bits * i, **defines})
                   for i in range(passes)]
        scatter_p = [ctx.compute_pipeline(f"{folder}_scatter.wgsl", {"SHIFT": digit_bits * i, **defines})
                     for i in range(passes)]
        scan_p = ctx.compute_pipeline("sort/radix_scan.wgsl", {"DIGITS": 1 << digit_bits,
                                                                "GROUP_BLOCKS": self.group_blocks})
        return digit_bits, count_p, scan_p, scatter_p

    def sort(self, keys: np.ndarray, values: np.ndarray | None = None, bits: int = 32, base: int | None = None,
             separate: bool = False):
        """Convenience: sort host arrays on the GPU (used by tests). Returns (keys, values).
        ``separate``: through encode's ``source`` instead of in place."""
        ctx = self.ctx
        keys = np.ascontiguousarray(keys, np.uint32)
        n = keys.size
        values = np.arange(n, dtype=np.uint32) if values is None else np.ascontiguousarray(values, np.uint32)
        if n == 0:
            return keys.copy(), values.copy()
        kb = ctx.upload(keys, "keys")
        vb = ctx.upload(values, "values")
        info = ctx.upload(dispatch_info(n, SORT_BLOCK), "sort.info",
                          wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.INDIRECT | wgpu.BufferUsage.COPY_DST)
        enc = ctx.device.create_command_encoder()
        based = (ctx.upload(np.array([base], np.uint32), "sort.base"), 0) if base is not None else None
        if separate:
            out_k, out_v = ctx.buffer(4 * n, "sorted_keys"), ctx.buffer(4 * n, "sorted_values")
            self.encode(enc, info, out_k, out_v, n, bits, base=based, source=(kb, vb))
            kb, vb = out_k, out_v
        else:
            self.encode(enc, info, kb, vb, n, bits, base=based)
        ctx.submit(enc)
        return ctx.read(kb, np.uint32, n), ctx.read(vb, np.uint32, n)
