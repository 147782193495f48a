"""The rasterizer's variants as one frozen value, chosen once from the adapter's features.

Every variant here is one that some adapter class needs: the subgroup rasterizers for CPU adapters
(lavapipe), the plain ones for GPUs and adapters without subgroups; the tile walk for 8-lane subgroups,
the per-subgroup variant for other sizes; gradient records where lavapipe runs subgroups one after another,
per-surfel atomics elsewhere; native float atomics or compare-and-swap; work queues on lavapipe, whose
threads share the CPU with everything else. :meth:`RasterOptions.for_context` picks what the adapter runs;
tests and benchmarks build other values with :func:`dataclasses.replace` to run the variants other
adapters take, and :meth:`RasterOptions.check` refuses one the adapter cannot run.

The options reach the shaders only as their preprocessor defines, so the context's pipeline cache (keyed
by the defines) keeps the pipelines of different options apart.
"""

from __future__ import annotations

from dataclasses import dataclass

from gma.gpu import GpuContext

# The subgroup rasterizers keep one round's ballot in a single u32 (rasterize_core.wgsl): at most 32 lanes.
MAX_SUBGROUP_LANES = 32
TILE_WALK_LANES = 8   # one subgroup composites a whole 16x16 tile (tile_walk_fwd.wgsl)


@dataclass(frozen=True)
class RasterOptions:
    """Which variant of each pass the rasterizer runs (see the module's text).

    ``subgroups``: the subgroup rasterizers (forward and backward). ``project_subgroups``: projection's frame
    stats by subgroup reductions rather than workgroup atomics. ``tile_walk``: with 8-lane subgroups, one
    subgroup per tile (also selects the walks' surfel layout and surfel textures). ``grad_records``: the
    tile walk's backward stores per-intersection gradient records instead of adding per-surfel atomics
    (safe on lavapipe only: store_record in tile_walk_bwd.wgsl). ``float_atomics``: native float atomics
    where the backward adds with atomics, else compare-and-swap. ``work_queues``: projection, emission,
    the tile walks and project_bwd take their work from a queue, with ``queue_workgroups`` workgroups
    (common/work_queue.wgsl).
    """

    subgroups: bool = False
    project_subgroups: bool = False
    tile_walk: bool = False
    grad_records: bool = False
    float_atomics: bool = False
    work_queues: bool = False
    queue_workgroups: int = 1

    @classmethod
    def for_context(cls, ctx: GpuContext) -> RasterOptions:
        """The variants this adapter runs best. Subgroup shuffles pay off where workgroup memory reads are
        slow (CPU drivers); on GPUs those reads are broadcasts and the plain loop is simpler (and the
        subgroup variant is validated on lavapipe only)."""
        lanes = ctx.subgroup_size
        subgroups = ctx.is_software and 1 <= lanes <= MAX_SUBGROUP_LANES
        tile_walk = subgroups and lanes == TILE_WALK_LANES
        return cls(subgroups=subgroups, project_subgroups=ctx.has_subgroups, tile_walk=tile_walk,
                   grad_records=tile_walk and ctx.is_lavapipe, float_atomics=ctx.has_float_atomics,
                   work_queues=ctx.is_lavapipe, queue_workgroups=ctx.dispatch_threads)

    def check(self, ctx: GpuContext) -> None:
        """Raise ValueError when ``ctx``'s adapter cannot run these options."""
        lanes = ctx.subgroup_size
        problems = []
        if (self.subgroups or self.project_subgroups) and not ctx.has_subgroups:
            problems.append("subgroup variants on an adapter without subgroups")
        if self.subgroups and not 1 <= lanes <= MAX_SUBGROUP_LANES:
            problems.append(f"subgroup rasterizers with {lanes}-lane subgroups (at most {MAX_SUBGROUP_LANES})")
        if self.tile_walk and not (self.subgroups and lanes == TILE_WALK_LANES):
            problems.append(f"the tile walk needs the subgroup rasterizers with {TILE_WALK_LANES}-lane subgroups")
        if self.grad_records and not (self.tile_walk and ctx.is_lavapipe):
            problems.append("gradient records need the tile walk on lavapipe")
        if self.float_atomics and not ctx.has_float_atomics:
            problems.append("native float atomics on an adapter without them")
        if not 1 <= self.queue_workgroups <= 65535:
            problems.append(f"queue_workgroups {self.queue_workgroups} outside 1..65535")
        if problems:
            raise ValueError(f"RasterOptions not runnable on {ctx.name}: {'; '.join(problems)}")
