"""The forward surfel rasterizer: projection, depth sort, tile binning, tile sort, tiled compositing.

Every pass runs on the GPU. :meth:`SurfelRasterizer.forward` sizes the intersection lists and the depth
sort's radix passes by what earlier renders needed, checks projection's counts after the render and runs
the part after projection again, exactly sized, when a render needed more. The texture path
(:meth:`render_to_texture`) reads nothing back, using a capacity that grows from earlier frames.
"""

from __future__ import annotations

import math
import weakref
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import wgpu

from gma.core.camera import Camera
from gma.gpu import GpuContext, PassTimer
from gma.gpu.context import STORAGE
from gma.gpu.mapped_reads import PackedBuffer
from gma.gpu.workspace import Workspace
from gma.render.gpu_scan import ExclusiveScan
from gma.render.gpu_sort import SORT_BLOCK, RadixSorter, dispatch_info
from gma.render.layouts import render_params, tile_grid
from gma.render.options import RasterOptions
from gma.render.surfel_texels import COLORS_BINDING, SurfelTexels, TexelLease
from gma.render.surfels import SurfelBuffers

UNIFORM = wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST
INDIRECT = wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.INDIRECT | wgpu.BufferUsage.COPY_DST
MAX_WORKGROUPS = 65535
MAX_SURFELS = MAX_WORKGROUPS * 256  # one projection thread per surfel; also keeps ids below 2^SURFEL_ID_BITS
MAX_IMAGE_SIDE = 65535  # project_fwd.wgsl packs 4x2-block coordinates in 16 bits (rasterize() already caps at 16384)
DEPTH_KEY_BITS = 24  # depth_key() in project_fwd.wgsl
RASTER_THREADS_SUBGROUPS = 64  # threads per tile of the subgroup rasterizers (RASTER_THREADS in rasterize_core.wgsl)
RECORD_KEY_SHIFT = 16  # render_types.wgsl: bits of a record-carrying intersection key that hold the tile
SURFEL_ID_BITS = 24  # render_types.wgsl: bits of a listed surfel id below its block bits (block_bits.wgsl)


@dataclass
class ProjectionState:
    """GPU buffers written by projection, depth sort and the tile-count scan (by surfel, or depth order)."""

    params: wgpu.GPUBuffer        # RenderParams uniform
    projected: wgpu.GPUBuffer     # [N] ProjectedSurfel (with walk_layout the colour in place of normal, depth)
    tile_rects: wgpu.GPUBuffer    # [N] vec4<u32>
    block_bands: wgpu.GPUBuffer   # [N] vec2<u32>: per 8-row band the 4-pixel columns where alpha >= 1/255 can be
    colors4: wgpu.GPUBuffer       # [N] vec4<f32> colour channels 0-3, zero-padded (depth in w below 4
                                  # channels); with walk_layout the normal and depth
    pixel_rows: wgpu.GPUBuffer | None  # [N] u32: the box's first | last pixel row << 16 (the forward's tile walk)
    tile_counts: wgpu.GPUBuffer   # [N]
    depth_keys: wgpu.GPUBuffer    # [N] sorted
    depth_order: wgpu.GPUBuffer   # [N] surfel ids, front to back
    isect_offsets: wgpu.GPUBuffer  # [N] exclusive scan of tile counts in depth order
    stats: wgpu.GPUBuffer         # [4] u32: [0], [1] intersections wanted, [2] min and [3] max depth key
    sort_info: wgpu.GPUBuffer     # DispatchInfo of the intersection sort (count clamped to capacity)
    elem_info: wgpu.GPUBuffer     # DispatchInfo of per-intersection passes
    # Those of the above taken from the recycler for the caller to keep (project(keep=True)); forward()
    # gives them back with its state.
    kept: list[wgpu.GPUBuffer] = field(default_factory=list)
    # Whether the tile walks render these (TILE_WALK) and projection wrote their layout of projected and
    # colors4 (WALK_LAYOUT in project_fwd.wgsl, always with the tile walks): the passes that read them are
    # compiled to match.
    tile_walk: bool = False
    walk_layout: bool = False


@dataclass
class RecordIndex:
    """What a render's backward pass needs to write and find per-intersection gradient records (see
    tile_walk_bwd.wgsl): a record lies at its intersection's tile-sorted place, and the backward's slots,
    by emission index (record_base[surfel] + the intersection's number within its surfel's list, which
    its tile-sorted key carries), point to it, so that a surfel's slots are consecutive."""

    isect_keys: wgpu.GPUBuffer    # tile-sorted: tile | number << RECORD_KEY_SHIFT
    record_base: wgpu.GPUBuffer   # [N] by surfel id (written for listed surfels only)
    used_blocks: wgpu.GPUBuffer   # tile-sorted: the blocks where a pixel took the surfel (tile_walk_fwd.wgsl)


@dataclass
class ForwardState:
    """Exactly what the backward pass needs from a forward render, plus the output images."""

    camera: Camera
    num_surfels: int
    channels: int
    num_isects: int
    proj: ProjectionState
    isect_ids: wgpu.GPUBuffer     # tile-sorted surfel ids (low 24 bits; the subgroup variant's block bits above)
    tile_ranges: wgpu.GPUBuffer   # [num_tiles] vec2<u32>
    background: wgpu.GPUBuffer    # [C]
    color: wgpu.GPUBuffer         # [H, W, C]
    alpha: wgpu.GPUBuffer         # [H, W]
    normal: wgpu.GPUBuffer        # [H, W, 3]
    depth: wgpu.GPUBuffer         # [H, W]
    final_t: wgpu.GPUBuffer | None  # [H, W] (None: rendered with replay=False)
    last: wgpu.GPUBuffer | None     # [H, W] contributors per pixel (u32)
    records: RecordIndex | None = None  # the backward sums gradient records (else per-surfel atomics)
    host_images: ImageOutputs | None = None  # read with the render's counts (forward(read_images=True))
    texel_lease: TexelLease | None = None  # the tile walks' surfel textures of this render (surfel_texels.py)


def _record_bytes(num_isects: int, normal_depth: bool) -> int:
    """Bytes of a backward pass's gradient records (store_record in tile_walk_bwd.wgsl): per
    intersection 16 values, and with normal/depth gradients 4 colours after them."""
    return 4 * (20 if normal_depth else 16) * max(num_isects, 1)


def _bits_for(count: int) -> int:
    return max(1, math.ceil(math.log2(max(count, 2))))


def depth_key_bits(stats: np.ndarray) -> int:
    """Bits of ``key - min`` that the depth sort must order, from projection's ``stats`` (see
    project_fwd.wgsl): the keys of all surfels listed in some tile lie in [min, max], so a stable sort
    of ``key - min`` by its low ``(max - min).bit_length()`` bits orders them exactly as the full key
    would: same order, images bit-identical. Surfels in no tile (culled ones included) land anywhere:
    they emit no intersection. Standard scene (depths 2.5-3.5): 18 bits, 5 radix passes instead of 6."""
    if stats[1] == 0:
        return 1
    return max(1, (int(stats[3]) - int(stats[2])).bit_length())


class SurfelRasterizer:
    """Renders :class:`SurfelBuffers` for a :class:`Camera`. Pipelines are compiled once per context
    and variant (channel count, batch size); a frame compiles nothing."""

    def __init__(self, ctx: GpuContext, options: RasterOptions | None = None):
        """``options``: the variants to run (default: :meth:`RasterOptions.for_context`, what this adapter
        runs best); refused with ValueError when the adapter cannot run them."""
        self.ctx = ctx
        self.options = RasterOptions.for_context(ctx) if options is None else options
        self.options.check(ctx)
        self.workspace = Workspace(ctx)
        self.sorter = RadixSorter(ctx, self.workspace)
        self.scan = ExclusiveScan(ctx, self.workspace)
        self.isect_capacity_hint = 1 << 16
        self.depth_bits_hint = 1   # key bits the depth sort orders (forward)
        self.texels = SurfelTexels(ctx)
        self.last_timings: dict[str, float] = {}

    # -- variants -----------------------------------------------------------------------------------
    def raster_defines(self, channels: int) -> dict:
        """Rasterizer variant: a batch size that fits the adapter's workgroup memory (the plain path: 64
        B per surfel, 4 B of surfel id in the backward, 16 B per 4 channels; the subgroup path, which
        stages no surfel data: 4 B of block mask plus a 4 B hit-list entry per subgroup, and SG entries
        of scratch per subgroup), and the subgroup path on CPU adapters (see rasterize_core.wgsl). On
        lavapipe smaller batches than 256 were slower and larger ones no faster (docs/design.md)."""
        limit = int(self.ctx.limits["max-compute-workgroup-storage-size"])
        sg = self.ctx.subgroup_size if self.options.subgroups and channels <= 4 else 0
        per_surfel = 4 + 4 * (RASTER_THREADS_SUBGROUPS // sg) if sg else 68 + 16 * ((channels + 3) // 4)
        batch = 256  # at most: the subgroup path packs a hit's batch slot into 8 bits (hit_entry)
        fixed = 64 + (4 * RASTER_THREADS_SUBGROUPS if sg else 0)
        while batch > 32 and batch * per_surfel + fixed > limit:
            batch //= 2
        defines = {"CHANNELS": channels, "BATCH": batch, "USE_SUBGROUPS": False, "SG": 1, "TILE_WALK": False,
                   "WALK_LAYOUT": False}
        if sg:
            # 8 lanes (lavapipe): one subgroup composites a whole tile (tile_walk_fwd.wgsl), reading the
            # surfels in the walks' layout (surfel_texels.wgsl: one cache line per surfel in the backward).
            tile_walk = self.options.tile_walk
            defines.update(USE_SUBGROUPS=True, SG=sg, TILE_WALK=tile_walk, WALK_LAYOUT=tile_walk)
        defines["WORK_QUEUE"] = defines["TILE_WALK"] and self.options.work_queues
        return defines

    def _records_for(self, camera: Camera, channels: int, num_isects: int) -> bool:
        """Whether a replayed render keeps the index for gradient records: the lavapipe subgroup
        variant's tile walk, tile ids that fit below RECORD_KEY_SHIFT, and records that fit one buffer
        binding."""
        tx, ty = tile_grid(camera.width, camera.height)
        largest = _record_bytes(num_isects, normal_depth=True)
        return (self.options.grad_records and self.raster_defines(channels)["TILE_WALK"]
                and tx * ty <= 1 << RECORD_KEY_SHIFT and largest <= self.ctx.max_binding_bytes)

    # -- passes -------------------------------------------------------------------------------------
    def _dispatch(self, encoder, pipeline, buffers, groups, name, timer):
        cp = encoder.begin_compute_pass(timestamp_writes=timer.writes(name) if timer else None)
        cp.set_pipeline(pipeline)
        cp.set_bind_group(0, self.ctx.bind_group(pipeline, buffers))
        if isinstance(groups, wgpu.GPUBuffer):
            cp.dispatch_workgroups_indirect(groups, 0)
        else:
            cp.dispatch_workgroups(*groups)
        cp.end()

    def _groups(self, encoder, resources: dict, queued: bool, binding: int, groups: tuple[int, int, int]
                ) -> tuple[int, int, int]:
        """The workgroups of a dispatch: ``groups``, or for a pass that takes its work from a queue
        (common/work_queue.wgsl) one per driver thread, with the queue's counter at ``binding``, cleared here
        (the queue runs the clear and the pass in order, so passes of other renders between do not matter)."""
        if not queued:
            return groups
        counter = self.workspace.get("work_queue", 16)
        encoder.clear_buffer(counter, 0, 16)
        resources[binding] = counter
        return (self.options.queue_workgroups, 1, 1)

    @staticmethod
    def _subgroup_inputs(resources: dict, colors4: wgpu.GPUBuffer, pixel_rows: wgpu.GPUBuffer | None = None) -> None:
        """The subgroup rasterizers (forward and backward) read the colours padded to a vec4 that
        projection wrote (see rasterize_core.wgsl) instead of the colours at binding 2, which they do not
        declare; the forward's tile walk also reads the surfels' pixel rows."""
        del resources[2]
        resources[15] = colors4
        if pixel_rows is not None:
            resources[18] = pixel_rows

    def project(self, encoder, surfels: SurfelBuffers, camera: Camera, capacity: int,
                timer: PassTimer | None = None, keep: bool = True) -> ProjectionState:
        """Encode projection (then :meth:`depth_order` sorts). With ``keep`` the buffers the backward pass
        reads are allocated for this call; the rest is workspace scratch."""
        ctx, n = self.ctx, surfels.count
        if n > MAX_SURFELS:  # tested against SURFEL_ID_BITS in test_render_layouts.py
            raise ValueError(f"{n} surfels exceed this renderer's limit of {MAX_SURFELS}")
        if max(camera.width, camera.height) > MAX_IMAGE_SIDE:
            raise ValueError(f"a {camera.width}x{camera.height} image exceeds this renderer's limit of "
                             f"{MAX_IMAGE_SIDE} pixels per side")
        params = render_params(camera.viewmat, camera.K, camera.width, camera.height, n, capacity,
                               surfels.channels)
        scratch = self.workspace.get
        taken: list[wgpu.GPUBuffer] = []
        variant = self.raster_defines(surfels.channels)
        tile_walk = variant["TILE_WALK"]

        def kept(label, nbytes, usage=STORAGE):
            if not keep:
                return scratch(label, nbytes, usage)
            taken.append(ctx.recycler.take(nbytes, label, usage))
            return taken[-1]

        st = ProjectionState(
            params=kept("params", params.nbytes, UNIFORM),
            projected=kept("projected", 64 * n),
            tile_rects=scratch("tile_rects", 16 * n),
            block_bands=scratch("block_bands", 8 * n),
            colors4=kept("colors4", 16 * n),
            pixel_rows=scratch("pixel_rows", 4 * n) if tile_walk else None,
            tile_counts=kept("tile_counts", 4 * n),
            depth_keys=scratch("depth_keys", 4 * n),
            depth_order=scratch("depth_order", 4 * n),
            isect_offsets=scratch("isect_offsets", 4 * n),
            stats=scratch("stats", 16),
            sort_info=scratch("isect_sort.info", 16, INDIRECT),
            elem_info=scratch("isect_elem.info", 16, INDIRECT),
            kept=taken,
            tile_walk=tile_walk,
            walk_layout=variant["WALK_LAYOUT"],
        )
        ctx.write(st.params, params)
        ctx.write(st.stats, np.array([0, 0, 0xFFFFFFFF, 0], np.uint32))  # see project_fwd.wgsl
        if n == 0:
            return st
        # (the queue's variant uses subgroups)
        queued = self.options.project_subgroups and self.options.work_queues
        p = ctx.compute_pipeline("render/project_fwd.wgsl", {"USE_SUBGROUPS": self.options.project_subgroups,
                                                             "PIXEL_ROWS": tile_walk,
                                                             "WALK_LAYOUT": st.walk_layout,
                                                             "WORK_QUEUE": queued})
        resources = dict(enumerate([st.params, surfels.means, surfels.quats, surfels.scales, surfels.opacities,
                                    st.projected, st.tile_rects, st.tile_counts, st.depth_keys,
                                    st.depth_order, st.block_bands, surfels.colors, st.colors4, st.stats]))
        if tile_walk:
            resources[14] = st.pixel_rows
        groups = self._groups(encoder, resources, queued, 15, ((n + 255) // 256, 1, 1))
        self._dispatch(encoder, p, resources, groups, "project", timer)
        return st

    def depth_order(self, encoder, st: ProjectionState, n: int, key_bits: int = DEPTH_KEY_BITS,
                    timer: PassTimer | None = None) -> None:
        """Encode the depth sort by the low ``key_bits`` of ``key - min key`` (see :func:`depth_key_bits`)
        and the scan of tile counts in depth order."""
        if n == 0:
            return
        depth_info = self.workspace.get("depth_sort.info", 16, INDIRECT)
        self.ctx.write(depth_info, dispatch_info(n, SORT_BLOCK))
        self.sorter.encode(encoder, depth_info, st.depth_keys, st.depth_order, n, key_bits, timer,
                           base=(st.stats, 2))
        self.scan.encode(encoder, st.tile_counts, st.isect_offsets, n, index=st.depth_order, timer=timer)

    def _setup(self, encoder, st: ProjectionState, timer) -> None:
        setup = self.ctx.compute_pipeline("render/isect_setup.wgsl")
        self._dispatch(encoder, setup, [st.params, st.isect_offsets, st.tile_counts, st.depth_order,
                                        st.sort_info, st.elem_info, st.stats], (1, 1, 1), "bin", timer)

    def bin_and_rasterize(self, encoder, surfels: SurfelBuffers, camera: Camera, st: ProjectionState,
                          capacity: int, background: wgpu.GPUBuffer, target, timer: PassTimer | None = None):
        """Encode intersection emission, the tile sort, tile ranges and the rasterizer. ``target`` is a
        list of output buffers (buffer variant: colour, alpha, normal, depth, and for a render the backward
        pass will replay, the final transmittance and contributor count) or a GPUTextureView (texture
        variant, never replayed). Returns the tile-sorted surfel ids (for the subgroup variant with each
        intersection's block bits above bit 24, block_bits.wgsl), the tile ranges and, for a replayed render
        whose backward will sum gradient records (:meth:`_records_for`), their :class:`RecordIndex`."""
        ctx, n = self.ctx, surfels.count
        tx, ty = tile_grid(camera.width, camera.height)
        cap = max(capacity, 1)
        replay = not isinstance(target, wgpu.GPUTextureView) and len(target) == 6
        records = None
        if not replay:  # nothing outlives the frame: reuse
            isect_tiles = self.workspace.get("isect_tiles", 4 * cap)
            isect_ids = self.workspace.get("isect_ids", 4 * cap)
            ranges = self.workspace.get("tile_ranges", 8 * tx * ty)
        else:  # kept in the ForwardState for the backward pass (recycled with it, see forward)
            take = ctx.recycler.take
            isect_ids = take(4 * cap, "isect_ids", STORAGE)
            ranges = take(8 * tx * ty, "tile_ranges", STORAGE)
            if self._records_for(camera, surfels.channels, capacity):
                records = RecordIndex(take(4 * cap, "isect_keys", STORAGE), take(4 * max(n, 1), "record_base", STORAGE),
                                      take(4 * cap, "used_blocks", STORAGE))
            isect_tiles = records.isect_keys if records else self.workspace.get("isect_tiles", 4 * cap)
        keyed = {"RECORD_KEYS": records is not None}
        defines = {**self.raster_defines(surfels.channels), "TILE_WALK": st.tile_walk, "WALK_LAYOUT": st.walk_layout}
        subgroups = defines["USE_SUBGROUPS"]
        empty = self.workspace.get("empty", 64)
        if n > 0:
            self._setup(encoder, st, timer)
            queued = subgroups and self.options.work_queues   # the queue's variant is the subgroup one
            emit = ctx.compute_pipeline("render/emit_isects.wgsl", {**keyed, "BLOCK_BITS": subgroups,
                                                                     "WORK_QUEUE": queued})
            # Emission writes scratch lists that the tile sort reads, and the sort writes the kept ones
            # (no copy back after its one pass on lavapipe: gpu_sort.py); one spare entry past the capacity
            # takes the subgroup variant's stores of tiles it does not list (emit_isects.wgsl).
            emitted = (self.workspace.get("emitted_tiles", 4 * cap + 4), self.workspace.get("emitted_ids", 4 * cap + 4))
            emit_resources = dict(enumerate([st.params, st.depth_order, st.isect_offsets, st.tile_counts,
                                             st.tile_rects, *emitted]))
            if records:
                emit_resources[7] = records.record_base
            if subgroups:
                emit_resources[8] = st.block_bands
            groups = self._groups(encoder, emit_resources, queued, 9, ((n + 255) // 256, 1, 1))
            self._dispatch(encoder, emit, emit_resources, groups, "bin", timer)
            self.sorter.encode(encoder, st.sort_info, isect_tiles, isect_ids, cap, _bits_for(tx * ty), timer,
                               source=emitted)
            rng = ctx.compute_pipeline("render/tile_ranges.wgsl", keyed)  # writes every tile's range
            self._dispatch(encoder, rng, [st.elem_info, isect_tiles, ranges, st.params],
                           ((tx * ty + 255) // 256, 1, 1), "bin", timer)
        else:
            encoder.clear_buffer(ranges)  # every tile is empty
        texels = self._texels_for(defines, n)
        defines = {**defines, "SURFEL_TEXELS": texels is not None}
        inputs = [st.params, st.projected if n else empty, surfels.colors, isect_ids, ranges, background]
        if isinstance(target, wgpu.GPUTextureView):
            raster = ctx.compute_pipeline("render/rasterize_texture.wgsl", defines)
            resources = dict(enumerate(inputs + [target]))
        else:
            raster = ctx.compute_pipeline("render/rasterize_fwd.wgsl", {**defines, "REPLAY": replay,
                                                                        "USED_BLOCKS": records is not None})
            resources = dict(enumerate(inputs + list(target)))
            if records:
                resources[19] = records.used_blocks
        if subgroups:
            self._subgroup_inputs(resources, st.colors4 if n else empty,
                                  (st.pixel_rows if n else empty) if defines["TILE_WALK"] else None)
        lease = texels.bind(encoder, resources, st.projected, st.colors4, n, lease=replay) if texels else None
        groups = self._groups(encoder, resources, defines["WORK_QUEUE"], 24, (tx, ty, 1))
        self._dispatch(encoder, raster, resources, groups, "rasterize", timer)
        return isect_ids, ranges, records, lease

    def _texels_for(self, defines: dict, n: int) -> SurfelTexels | None:
        """The surfel textures for a rasterizer variant, or None where it reads the buffers: only the
        tile walks (lavapipe) read textures, and only while the surfels fit them."""
        if not (defines["TILE_WALK"] and 0 < n <= self.texels.capacity):
            return None
        return self.texels

    # -- public entry points ------------------------------------------------------------------------
    def forward(self, surfels: SurfelBuffers, camera: Camera, background: np.ndarray | None = None,
                timer: PassTimer | None = None, replay: bool = True, read_images: bool = False,
                while_projecting: Callable[[], None] | None = None) -> ForwardState:
        """Render (read the images with :func:`read_outputs`). With ``replay`` (the default) the state
        keeps freshly allocated buffers, everything :meth:`backward` needs. Without it the images land
        in scratch buffers that the next render overwrites (read them first), nothing for a backward
        pass is written or kept, and the rasterizer drops the contributor counting (faster);
        :meth:`backward` refuses such a state.

        Two submissions, no host round trip between them: projection, then, encoded while the GPU
        projects, depth sort, scan, binning, tile sort and rasterization, sized by what earlier renders
        needed (the intersection capacity and the depth sort's key bits, :func:`depth_key_bits`). Then
        it reads projection's counts: when this render needed more, the part after projection runs
        again with exact sizes (the first render, or a larger scene) and the hints grow. (Reading them
        between the submissions would leave the GPU idle while the second part is encoded.) With
        ``read_images`` the images come back in the same
        transfer as the counts (one device round trip fewer; read again after a rerun), and
        :func:`read_outputs` returns them. ``while_projecting`` runs on the host after projection is
        submitted and before the rest is (the public call checks the surfels' values there, off the
        critical path: an exception from it leaves only projection's work behind)."""
        ctx, n, c = self.ctx, surfels.count, surfels.channels
        bg = np.zeros(c, np.float32) if background is None else np.asarray(background, np.float32)
        capacity, key_bits = self.isect_capacity_hint, self.depth_bits_hint
        enc = ctx.device.create_command_encoder()
        st = self.project(enc, surfels, camera, capacity, timer, keep=replay)
        ctx.submit(enc)
        if while_projecting is not None:
            while_projecting()
        timed_projection = list(timer.names) if timer else []
        hw = camera.width * camera.height
        def image(label, nbytes):  # kept for the backward pass, or scratch that the next render reuses
            return ctx.recycler.take(nbytes, label, STORAGE) if replay else self.workspace.get(label, nbytes)

        # The rasterizer writes every pixel of these (recycled buffers hold an earlier render's values).
        # Read in place (CPU adapters): ranges of one mappable buffer, after the projection's counts, whose
        # mapping the returned arrays are (gma/gpu/mapped_reads.py).
        in_place = read_images and ctx.reads_in_place
        if in_place:
            packed = self._packed_images(hw, c)
            images = packed.bindings[1:]
        else:
            images = [image("out.color", image_bytes(hw * c)), image("out.alpha", image_bytes(hw)),
                      image("out.normal", image_bytes(3 * hw)), image("out.depth", image_bytes(hw))]
        replayed = [image("out.final_t", image_bytes(hw)), image("out.last", image_bytes(hw))] if replay else []
        background_buf = ctx.constant(bg, "background")  # never written: states of earlier renders share it
        lists = self._sort_bin_rasterize(surfels, camera, st, capacity, key_bits, background_buf,
                                         images + replayed, timer, packed if in_place and n else None)
        image_reads = _image_reads(images, camera, c) if read_images and not in_place else []
        stats, host = self._read_counts_and_images(st, packed if in_place else None, image_reads, n)
        num_isects, needed_bits = int(stats[1]), depth_key_bits(stats)
        del stats   # (with in-place reads a view of the images' mapping)
        # Exact from here on: the backward's passes bound the intersection lists by it.
        ctx.write(st.params, np.array([num_isects], np.uint32), offset=CAPACITY_OFFSET)
        if num_isects > capacity or needed_bits > key_bits:
            if timer:  # report the passes that ran last
                timer.names = timed_projection
            if lists[3] is not None:   # the texels' lease of the render that is done again
                self.texels.give_back(lists[3])
            if in_place:   # the first images' buffer stays mapped until their arrays are gone
                del host
                packed = self._packed_images(hw, c)
                images = packed.bindings[1:]
            lists = self._sort_bin_rasterize(surfels, camera, st, num_isects, needed_bits, background_buf,
                                             images + replayed, timer)
            if in_place:
                host = self._read_packed(packed, counted=False)[1]
            else:
                host = ctx.read_many(image_reads)
        # Hints only grow, so that views of one scene with more or fewer intersections do not render twice.
        self.isect_capacity_hint = max(self.isect_capacity_hint, num_isects)
        self.depth_bits_hint = max(self.depth_bits_hint, needed_bits)
        isect_ids, ranges, records, lease = lists
        state = ForwardState(camera, n, c, num_isects, st, isect_ids, ranges, background_buf, *images,
                             *(replayed or (None, None)), records=records,
                             host_images=_images_from(host, camera, c) if read_images else None,
                             texel_lease=lease)
        self._hand_back_with(state, lease, [*st.kept, isect_ids, ranges, *([] if in_place else images), *replayed]
                             if replay else None)
        return state

    def _read_counts_and_images(self, st, packed: PackedBuffer | None, image_reads: list, n: int):
        """A render's projection counts and (where asked) its images, in one transfer: from the mapped
        ``packed`` buffer when the images were written there, else through ``image_reads``. No surfels, no
        counts (zeros)."""
        if packed is not None:
            return self._read_packed(packed, counted=n > 0)
        if n:
            stats, *host = self.ctx.read_many([(st.stats, np.uint32, 4)] + image_reads)
            return stats, host
        return np.zeros(4, np.uint32), self.ctx.read_many(image_reads)

    def _hand_back_with(self, state: ForwardState, lease, kept: list | None) -> None:
        """When ``state`` is gone, give back its surfel texels' ``lease`` (the backward binds them) and, for
        a replayable render, its ``kept`` buffers and records: they serve later renders (a training loop
        then allocates nothing; see gma/gpu/recycle.py). Each is written in full before it is read:
        projection writes every surfel's tile count, and the rest is read only where tile counts, lists
        and ranges point, which that render wrote."""
        if lease is not None:
            done = weakref.finalize(state, self.texels.give_back, lease)
            done.atexit = False
        if kept is not None:
            records = state.records
            if records:
                kept += [records.isect_keys, records.record_base, records.used_blocks]
            self.ctx.recycler.release_with(state, kept)

    def _packed_images(self, hw: int, c: int) -> PackedBuffer:
        """A mappable buffer for a render's counts (16 bytes, range 0) and its four images (ranges 1-4)."""
        return self.ctx.mapped_reads.take_packed([16, *(image_bytes(k * hw) for k in (c, 1, 3, 1))], "out.images",
                                                 reuse=self.ctx.recycler.enabled)

    def _read_packed(self, packed: PackedBuffer, counted: bool):
        """Read a render's images in place, and its counts where :meth:`_sort_bin_rasterize` copied them in
        front (``counted``; zeros otherwise): (counts, [color, alpha, normal, depth]) as flat arrays over the
        mapping."""
        counts, *images = self.ctx.read_in_place(packed)
        stats = counts.view(np.uint32) if counted else np.zeros(4, np.uint32)
        return stats, [a.view(np.float32) for a in images]

    def _sort_bin_rasterize(self, surfels, camera, st, capacity, key_bits, background_buf, targets, timer,
                            counts_to: PackedBuffer | None = None):
        """Encode and submit everything after projection (see :meth:`forward`): the depth sort by
        ``key_bits``, then binning into lists of ``capacity`` intersections and rasterization; then
        projection's counts are copied to the front of ``counts_to`` (in the same submission: one of its own
        is one more round through lavapipe's queue before the images can be read)."""
        enc = self.ctx.device.create_command_encoder()
        self.depth_order(enc, st, surfels.count, key_bits, timer)
        lists = self.bin_and_rasterize(enc, surfels, camera, st, capacity, background_buf, targets, timer)
        if counts_to is not None:
            enc.copy_buffer_to_buffer(st.stats, 0, counts_to.buffer, 0, 16)
        if timer:
            timer.resolve(enc)
        self.ctx.submit(enc)
        return lists

    def backward(self, state: ForwardState, surfels: SurfelBuffers, v_color: np.ndarray | None,
                 v_alpha: np.ndarray | None, v_normal: np.ndarray | None, v_depth: np.ndarray | None,
                 timer: PassTimer | None = None) -> SurfelGrads:
        """Gradients of a scalar loss with respect to the surfels of a forward render, given its
        gradients with respect to the output images (None: zero). ``surfels`` must hold the same values
        as in the forward call. One submission plus the read-back of the gradients."""
        ctx, n, c = self.ctx, state.num_surfels, state.channels
        cam = state.camera
        hw = cam.width * cam.height
        if state.last is None:
            raise ValueError("this forward state was rendered with replay=False: it holds nothing to "
                             "backpropagate through")
        if n == 0:
            return SurfelGrads(*(np.zeros(shape, np.float32) for shape in ((0, 3), (0, 4), (0, 2), (0,), (0, c))))
        # Without a loss on the normal or depth images (or on the alpha image) the shader variant neither
        # reads their upstream gradients nor computes the terms they scale, so those buffers are not bound.
        normal_depth = v_normal is not None or v_depth is not None
        # This call's buffers go back to the recycler when it returns (gma/gpu/recycle.py): the upstream
        # gradients are uploaded in full and project_bwd writes every surfel's gradients. Accumulators
        # (the atomics' v_proj and v_colors) and a missing upstream's zeros are not recycled.
        take, recycled = ctx.recycler.take, []
        upstream = self._upload_upstream(v_color, v_alpha, v_normal, v_depth, c, hw, normal_depth, recycled)
        records = state.records
        tx, ty = tile_grid(cam.width, cam.height)
        defines, texels, record_bytes = self._backward_variant(state, normal_depth, v_alpha is not None)
        use_record_texels = defines["RECORD_TEXELS"]
        enc = ctx.device.create_command_encoder()
        raster = ctx.compute_pipeline("render/rasterize_bwd.wgsl", defines)
        resources = dict(enumerate([state.proj.params, state.proj.projected, surfels.colors, state.isect_ids,
                                    state.tile_ranges, state.background, state.final_t, state.last]))
        resources.update(upstream)
        # The subgroup variant without normal and depth gradients adds the colour gradients into their
        # slots of v_proj (fewer rounds of atomics, see rasterize_bwd.wgsl); project_bwd copies them out.
        # With records project_bwd writes every colour gradient. Otherwise the rasterizer's atomics add
        # them into a zero-filled v_colors.
        color_in_proj = defines["USE_SUBGROUPS"] and not normal_depth
        colors_out = color_in_proj or records is not None
        # project_bwd writes every gradient: with in-place reads into ranges of one mappable buffer, whose
        # mapping the returned arrays are (gma/gpu/mapped_reads.py).
        grad_sizes = [4 * k * n for k in (3, 4, 2, 1, c)]
        in_place = colors_out and ctx.reads_in_place
        if in_place:
            packed = ctx.mapped_reads.take_packed(grad_sizes, "v_surfels", reuse=ctx.recycler.enabled)
            *outs, v_colors = packed.bindings
        elif colors_out:
            v_colors = take(4 * c * n, "v_colors", STORAGE)
            recycled.append(v_colors)
        else:
            v_colors = ctx.buffer(4 * c * n, "v_colors")
        grads, slots = self._bind_gradient_sums(enc, resources, state, record_bytes, use_record_texels,
                                                None if colors_out else v_colors)
        if defines["USE_SUBGROUPS"]:
            self._subgroup_inputs(resources, state.proj.colors4)
        if texels and state.texel_lease is not None:   # the forward's copies, as they are
            texels.bind_lease(resources, state.texel_lease)
        elif texels:
            texels.bind(enc, resources, state.proj.projected, state.proj.colors4, n)
        if state.proj.walk_layout and not normal_depth:
            # In the walks' layout colors4 holds only the normal and depth, which this variant does not read.
            resources.pop(15, None)
            resources.pop(COLORS_BINDING, None)
        groups = self._groups(enc, resources, defines["WORK_QUEUE"], 24, (tx, ty, 1))
        self._dispatch(enc, raster, resources, groups, "rasterize_bwd", timer)
        if not in_place:
            outs = [take(size, name, STORAGE) for name, size in zip(("v_means", "v_quats", "v_scales", "v_opacities"),
                                                                     grad_sizes)]
            recycled += outs
        proj_defines = {"COLOR_IN_PROJ": color_in_proj, "GRAD_RECORDS": records is not None,
                        "RECORD_TEXELS": use_record_texels, "NORMAL_DEPTH_GRADS": normal_depth,
                        "COLORS_OUT": colors_out, "CHANNELS": c}
        links = {"grads": grads, "v_colors": v_colors if colors_out else None, "records": records,
                 "slots": slots, "record_texels": use_record_texels}
        self._project_backward(enc, state, surfels, outs, links, proj_defines, timer)
        ctx.submit(enc)
        grads_out = self._read_gradients(packed if in_place else None, [*outs, v_colors], n, c)
        ctx.recycler.give_back(recycled)  # read back: nothing else holds them
        return grads_out

    def _backward_variant(self, state: ForwardState, normal_depth: bool, alpha_grads: bool):
        """The backward shader's defines for a render as its forward ran, the surfel texels it reads (None
        without records) and the bytes of its gradient records."""
        records, n = state.records, state.num_surfels
        defines = self.backward_defines(state.channels)
        # As the forward rendered and laid out the surfels this pass reads.
        defines.update(TILE_WALK=state.proj.tile_walk, WALK_LAYOUT=state.proj.walk_layout)
        # With records the backward's entry point is the tile walk (tile_walk_bwd.wgsl, the only writer of
        # records); with atomics each subgroup replays its own block.
        defines.update(NORMAL_DEPTH_GRADS=normal_depth, ALPHA_GRADS=alpha_grads, GRAD_RECORDS=records is not None)
        # (Only the tile walk, the entry point with records, takes its tiles from a queue.)
        defines["WORK_QUEUE"] = records is not None and state.proj.tile_walk and self.options.work_queues
        texels = self._texels_for(defines, n) if records is not None else None
        defines["SURFEL_TEXELS"] = texels is not None
        # The records go to a texture that project_bwd reads (scattered reads; see surfel_texels.py).
        record_bytes = _record_bytes(state.num_isects, normal_depth)
        defines["RECORD_TEXELS"] = records is not None and record_bytes // 16 <= self.texels.max_texels
        return defines, texels, record_bytes

    def _bind_gradient_sums(self, enc, resources: dict, state: ForwardState, record_bytes: int,
                            use_record_texels: bool, atomic_colors) -> tuple:
        """Bind where the backward rasterizer puts its per-surfel sums: the records and their slots (the
        records variant), or a zero-filled v_proj for the atomics, plus ``atomic_colors`` (the colour
        gradients the atomics add into, when project_bwd does not write them). Returns (sums, slots)."""
        records = state.records
        if not records:
            grads = self.ctx.buffer(4 * 16 * state.num_surfels, "v_proj")
            resources[12] = grads
            if atomic_colors is not None:
                resources[13] = atomic_colors
            return grads, None
        # Scratch (the gradients are read back before the backward returns). Only records that the slots
        # point to are read, all written by this pass: no clearing; the slots are cleared.
        if use_record_texels:
            resources[23] = grads = self.texels.view("records", record_bytes // 16)
        else:
            resources[12] = grads = self.workspace.get("grad_records", record_bytes)
        slot_bytes = 4 * max(state.num_isects, 1)
        slots = self.workspace.get("record_slots", slot_bytes)
        enc.clear_buffer(slots, 0, slot_bytes)
        resources.update({16: records.isect_keys, 17: records.record_base, 19: records.used_blocks, 22: slots})
        return grads, slots

    def _read_gradients(self, packed, buffers: list, n: int, c: int) -> SurfelGrads:
        """The gradients of means, quats, scales, opacities and colours: the mappings of ``packed`` (reads
        in place) or a copy of ``buffers``."""
        if packed is not None:
            means, quats, scales, opacities, colors = (a.view(np.float32) for a in self.ctx.read_in_place(packed))
        else:
            means, quats, scales, opacities, colors = self.ctx.read_many(
                [(b, np.float32, k * n) for b, k in zip(buffers, (3, 4, 2, 1, c), strict=True)])
        return SurfelGrads(means.reshape(n, 3), quats.reshape(n, 4), scales.reshape(n, 2), opacities,
                           colors.reshape(n, c))

    def _upload_upstream(self, v_color, v_alpha, v_normal, v_depth, c: int, hw: int, normal_depth: bool,
                         recycled: list) -> dict:
        """The upstream image gradients as buffers by binding. A missing one that the variant still reads
        is a shared zero buffer; without a loss on the normal and depth images (or on alpha) the variant
        reads none, and nothing is bound. Uploaded buffers are appended to ``recycled``."""
        upstream = {}
        for binding, name, arr, per_pixel in ((8, "v_color", v_color, c), (9, "v_alpha", v_alpha, 1),
                                              (10, "v_normal", v_normal, 3), (11, "v_depth", v_depth, 1)):
            if (binding >= 10 and not normal_depth) or (binding == 9 and arr is None):
                continue
            if arr is None:
                upstream[binding] = self._zeros(4 * hw * per_pixel)
            else:
                data = np.ascontiguousarray(arr, np.float32).reshape(-1)
                upstream[binding] = self.ctx.recycler.take(data.nbytes, name, STORAGE)
                self.ctx.write(upstream[binding], data)
                recycled.append(upstream[binding])
        return upstream

    def _project_backward(self, enc, state: ForwardState, surfels: SurfelBuffers, outs: list, links: dict,
                          proj_defines: dict, timer) -> None:
        """Record project_bwd: from the rasterizer's per-surfel sums (``links["grads"]``: v_proj, or the
        records with their slots) to the gradients of means, quats, scales and opacities (``outs``) and,
        when ``links["v_colors"]`` is given, the colours; ends the encoder's timing."""
        n = state.num_surfels
        proj_resources = dict(enumerate([state.proj.params, surfels.means, surfels.quats, surfels.scales,
                                         state.proj.tile_counts, links["grads"], *outs]))
        if links["v_colors"] is not None:
            proj_resources[10] = links["v_colors"]
        if links["records"]:
            proj_resources[11] = links["records"].record_base
            proj_resources[12] = links["slots"]
        if links["record_texels"]:
            del proj_resources[5]
            proj_resources[13] = links["grads"]
        proj_defines["WORK_QUEUE"] = queued = self.options.work_queues and self.ctx.has_subgroups
        colors_out = links["v_colors"] is not None
        proj = self.ctx.compute_pipeline("render/project_bwd.wgsl", proj_defines if colors_out or queued else None)
        groups = self._groups(enc, proj_resources, queued, 14, ((n + 255) // 256, 1, 1))
        self._dispatch(enc, proj, proj_resources, groups, "project_bwd", timer)
        if timer:
            timer.resolve(enc)

    def _zeros(self, nbytes: int) -> wgpu.GPUBuffer:
        """A zero-filled buffer of at least ``nbytes`` that nothing writes (a missing upstream gradient)."""
        return self.workspace.get("zeros", nbytes)

    def backward_defines(self, channels: int) -> dict:
        defines = self.raster_defines(channels)
        defines["FLOAT_ATOMICS"] = self.options.float_atomics
        return defines

    def render_to_texture(self, surfels: SurfelBuffers, camera: Camera, view: wgpu.GPUTextureView,
                          background: wgpu.GPUBuffer, timer: PassTimer | None = None) -> ProjectionState:
        """Render into an rgba8unorm storage texture in one submission, with no readback. Intersections
        beyond ``isect_capacity_hint`` are dropped; call :meth:`grow_capacity` with the returned state
        from time to time (it reads 4 bytes) to adapt the capacity."""
        enc = self.ctx.device.create_command_encoder()
        cap = self.isect_capacity_hint
        st = self.project(enc, surfels, camera, cap, timer, keep=False)
        self.depth_order(enc, st, surfels.count, DEPTH_KEY_BITS, timer)  # no readback: every key bit
        self.bin_and_rasterize(enc, surfels, camera, st, cap, background, view, timer)
        if timer:
            timer.resolve(enc)
        self.ctx.submit(enc)
        return st

    def needed_capacity(self, st: ProjectionState) -> int:
        """The intersections the frame of ``st`` needed (reads 4 bytes, so it waits for that frame)."""
        return int(self.ctx.read(st.stats, np.uint32, 1)[0])

    def reserve_capacity(self, needed: int) -> None:
        """Make later frames hold ``needed`` intersections, with room for a view that needs a little more."""
        if needed > self.isect_capacity_hint:
            self.isect_capacity_hint = int(needed * 1.25)

    def grow_capacity(self, st: ProjectionState) -> bool:
        """Raise the capacity hint to what a frame needed; True when that frame had dropped work."""
        before = self.isect_capacity_hint
        self.reserve_capacity(self.needed_capacity(st))
        return self.isect_capacity_hint != before


CAPACITY_OFFSET = 116  # byte offset of RenderParams.isect_capacity


@dataclass
class SurfelGrads:
    """Gradients with respect to the renderer inputs (float32 numpy): ``means`` [N, 3], ``quats`` [N, 4],
    ``scales`` [N, 2], ``opacities`` [N], ``colors`` [N, C]."""

    means: np.ndarray
    quats: np.ndarray
    scales: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray


@dataclass
class ImageOutputs:
    """Host copies of a forward render: ``color`` [H, W, C], ``alpha`` [H, W, 1], ``normal`` [H, W, 3],
    ``depth`` [H, W, 1] (float32 numpy)."""

    color: np.ndarray
    alpha: np.ndarray
    normal: np.ndarray
    depth: np.ndarray


def read_outputs(ctx: GpuContext, state: ForwardState) -> ImageOutputs:
    """Copy a forward render's images back to the host in one transfer (or return those that
    ``forward(read_images=True)`` read already)."""
    if state.host_images is not None:
        return state.host_images
    images = [state.color, state.alpha, state.normal, state.depth]
    return _images_from(ctx.read_many(_image_reads(images, state.camera, state.channels)), state.camera,
                        state.channels)


def _image_reads(images: list, camera: Camera, channels: int) -> list:
    """read_many items of the (color, alpha, normal, depth) image buffers."""
    hw = camera.width * camera.height
    return [(buf, np.float32, hw * k) for buf, k in zip(images, (channels, 1, 3, 1))]


def _images_from(arrays: list[np.ndarray], camera: Camera, channels: int) -> ImageOutputs:
    """The (color, alpha, normal, depth) images from flat arrays (read in place, they run on to the end of
    their padded ranges: :func:`image_bytes`)."""
    h, w = camera.height, camera.width
    color, alpha, normal, depth = (a[:h * w * k] for a, k in zip(arrays, (channels, 1, 3, 1)))
    return ImageOutputs(color.reshape(h, w, channels), alpha.reshape(h, w, 1), normal.reshape(h, w, 3),
                        depth.reshape(h, w, 1))


def image_bytes(values: int) -> int:
    """Bytes of an output image of ``values`` floats as the forward rasterizer binds it: whole vec4s (the
    shader declares its images as vec4 arrays, so that the tile walk stores four pixels at once; a partial
    last vec4 would lie outside the binding)."""
    return -(-4 * values // 16) * 16
