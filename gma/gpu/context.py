"""The GPU context: one wgpu device with the adapter's real limits, its optional features, the shader
library and the pipeline cache. Code that renders takes a ``GpuContext`` argument instead of reaching
for a global device."""

from __future__ import annotations

import os
import threading
from collections import OrderedDict
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field

import numpy as np
import wgpu

from gma.core.errors import DeviceError
from gma.gpu.adapter import NoAdapterError, describe, select_adapter
from gma.gpu.bind_groups import BindGroupCache
from gma.gpu.host_memory import HostMemoryPool
from gma.gpu.mapped_reads import MappedReads, PackedBuffer
from gma.gpu.recycle import BufferRecycler
from gma.gpu.shaders import ShaderLibrary
from gma.gpu.transfers import TransferStats

__all__ = ["GpuContext", "NoAdapterError", "get_context"]

# Optional features we use when the adapter has them; every use has a fallback path.
OPTIONAL_FEATURES = ("shader-float32-atomic", "subgroup", "timestamp-query")
# Storage buffers that can also be mapped (wgpu native): on CPU adapters only, whose buffers are all host
# memory, so that read-backs map outputs in place (gma/gpu/mapped_reads.py).
IN_PLACE_READS = "mappable-primary-buffers"

# Limits we raise to what the adapter offers (WebGPU defaults are far lower than real hardware).
class GpuMemoryError(DeviceError, MemoryError):
    """A buffer larger than the adapter allows (the message says which and what to reduce)."""


RAISED_LIMITS = (
    "max-texture-dimension-2d",
    "max-storage-buffer-binding-size",
    "max-buffer-size",
    "max-storage-buffers-per-shader-stage",
    "max-compute-workgroup-storage-size",
    "max-compute-invocations-per-workgroup",
    "max-compute-workgroup-size-x",
    "max-compute-workgroup-size-y",
    "max-compute-workgroups-per-dimension",
    "max-bind-groups",
)

STORAGE = wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.COPY_SRC | wgpu.BufferUsage.COPY_DST
CONSTANT_CACHE_ENTRIES = 64  # GpuContext.constant
STAGING_KEEP_BYTES = 64 << 20  # read_many keeps its staging buffer for reuse up to this size


@dataclass
class GpuContext:
    """A wgpu device plus what is needed to run the project's compute passes on it.

    Create with :meth:`create`; ``disable_features`` switches optional features off, which is how the
    tests exercise the fallback paths (e.g. compare-and-swap instead of native float atomics).
    """

    adapter: wgpu.GPUAdapter
    device: wgpu.GPUDevice
    features: frozenset[str]
    shaders: ShaderLibrary
    transfers: TransferStats = field(default_factory=TransferStats)
    allocated_bytes: int = 0  # running total of bytes requested through buffer(); benchmarks diff it
    _pipelines: dict = field(default_factory=dict, repr=False)
    _recycler: BufferRecycler | None = field(default=None, repr=False)
    bind_groups: BindGroupCache = field(default_factory=BindGroupCache, repr=False)
    _constants: OrderedDict = field(default_factory=OrderedDict, repr=False)
    _constants_lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _mapped_reads: MappedReads | None = field(default=None, repr=False)

    @classmethod
    def create(cls, preference: str | None = None, disable_features: tuple[str, ...] = ()) -> GpuContext:
        adapter = select_adapter(preference)
        wanted = [f for f in OPTIONAL_FEATURES if f in adapter.features and f not in disable_features]
        if (adapter.info.get("adapter_type") == "CPU" and IN_PLACE_READS in adapter.features
                and IN_PLACE_READS not in disable_features):
            wanted.append(IN_PLACE_READS)
        limits = {k: adapter.limits[k] for k in RAISED_LIMITS if k in adapter.limits}
        device = adapter.request_device_sync(
            label="gma", required_features=wanted, required_limits=limits
        )
        return cls(adapter=adapter, device=device, features=frozenset(wanted), shaders=ShaderLibrary())

    # -- capabilities -------------------------------------------------------------------------------
    @property
    def name(self) -> str:
        return describe(self.adapter)

    @property
    def is_software(self) -> bool:
        return self.adapter.info.get("adapter_type") == "CPU"

    @property
    def reads_in_place(self) -> bool:
        """Whether outputs can be written into mappable buffers and read without copies (mapped_reads.py)."""
        return IN_PLACE_READS in self.features

    @property
    def mapped_reads(self) -> MappedReads:
        if self._mapped_reads is None:
            self._mapped_reads = MappedReads(self.device)
        return self._mapped_reads

    def read_in_place(self, packed: PackedBuffer) -> list[np.ndarray]:
        """The ranges of a buffer from :meth:`MappedReads.take_packed`, once the GPU has written them, as
        uint8 arrays over its mapping (no copy; see mapped_reads.py)."""
        if self.transfers.wait_for_compute:   # as read_many: the timing counts the read, not the compute
            self.wait_idle()
        with self.transfers.download(packed.nbytes):
            return self.mapped_reads.read_packed(packed)

    @property
    def is_lavapipe(self) -> bool:
        """Mesa's software Vulkan driver (llvmpipe): its workgroups run on one CPU thread each, their
        subgroups one after another between barriers, which the renderer's gradient records rely on."""
        info = self.adapter.info
        return "llvmpipe" in f"{info.get('vendor', '')} {info.get('device', '')}".lower()

    @property
    def dispatch_threads(self) -> int:
        """CPU threads that split a compute dispatch's workgroups between them: lavapipe's LP_NUM_THREADS,
        by default one per CPU this process may run on (llvmpipe counts them so; at most LP_MAX_THREADS,
        32); 1 on other adapters. The workgroups of a pass that takes its work from a queue
        (common/work_queue.wgsl): a wrong count only leaves a thread idle or gives it nothing to take."""
        if not self.is_lavapipe:
            return 1
        wanted = os.environ.get("LP_NUM_THREADS", "").strip()
        if wanted.isdigit():
            count = int(wanted)
        else:
            count = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1)
        return max(1, min(count, 32))

    @property
    def has_float_atomics(self) -> bool:
        return "shader-float32-atomic" in self.features

    @property
    def has_subgroups(self) -> bool:
        return "subgroup" in self.features

    @property
    def subgroup_size(self) -> int:
        """Lanes per subgroup as a probe kernel sees them (0 without the subgroup feature)."""
        if not self.has_subgroups:
            return 0
        size = getattr(self, "_subgroup_size", None)
        if size is None:
            probe = self.compute_pipeline("common/subgroup_probe.wgsl")
            out = self.buffer(4, "subgroup_probe")
            enc = self.device.create_command_encoder()
            cp = enc.begin_compute_pass()
            cp.set_pipeline(probe)
            cp.set_bind_group(0, self.bind_group(probe, [out]))
            cp.dispatch_workgroups(1)
            cp.end()
            self.submit(enc)
            size = self._subgroup_size = int(self.read(out, np.uint32, 1)[0])
        return size

    @property
    def has_timestamps(self) -> bool:
        return "timestamp-query" in self.features

    @property
    def limits(self) -> dict:
        return self.device.limits

    @property
    def max_binding_bytes(self) -> int:
        return int(self.device.limits["max-storage-buffer-binding-size"])

    # -- pipelines ----------------------------------------------------------------------------------
    def compute_pipeline(
        self, path: str, defines: dict | None = None, entry_point: str = "main"
    ) -> wgpu.GPUComputePipeline:
        """The compute pipeline for WGSL file ``path`` (relative to ``shaders/wgsl``), cached by
        (path, defines, entry point) so that a frame never compiles anything."""
        key = (path, tuple(sorted((defines or {}).items())), entry_point)
        pipeline = self._pipelines.get(key)
        if pipeline is None:
            module = self.shaders.module(self.device, path, defines)
            pipeline = self.device.create_compute_pipeline(
                label=f"{path}:{entry_point}",
                layout=wgpu.AutoLayoutMode.auto,
                compute={"module": module, "entry_point": entry_point},
            )
            self._pipelines[key] = pipeline
        return pipeline

    def bind_group(self, pipeline: wgpu.GPUComputePipeline, resources: list | dict, group: int = 0):
        """A bind group binding ``resources[i]`` at ``@binding(i)`` (a list), or each ``{binding:
        resource}`` (a dict). A resource is a buffer, a (buffer, offset, size) range, or a texture view.
        Groups of buffers and views are made once and reused while those live (gma/gpu/bind_groups.py);
        groups with anything else (samplers) are made every time."""
        items = resources.items() if isinstance(resources, dict) else enumerate(resources)
        bindings, others = [], []
        for i, b in items:
            if isinstance(b, tuple):
                bindings.append((i, *b))
            elif isinstance(b, wgpu.GPUBuffer):
                bindings.append((i, b, 0, b.size))
            elif isinstance(b, wgpu.GPUTextureView):
                bindings.append((i, b, 0, 0))   # a view binds whole: no range
            else:
                others.append((i, b))

        def create():
            entries = [{"binding": i, "resource": {"buffer": res, "offset": offset, "size": size}
                        if isinstance(res, wgpu.GPUBuffer) else res} for i, res, offset, size in bindings]
            entries += [{"binding": i, "resource": res} for i, res in others]
            return self.device.create_bind_group(layout=pipeline.get_bind_group_layout(group), entries=entries)

        if others:
            return create()
        return self.bind_groups.get(pipeline, group, bindings, create)

    def check_image_size(self, width: int, height: int, what: str = "image") -> None:
        """Refuse, before any texture is made, an image the adapter cannot hold (wgpu would abort the
        process instead of raising)."""
        limit = int(self.device.limits["max-texture-dimension-2d"])
        if not (1 <= width <= limit and 1 <= height <= limit):
            raise DeviceError(f"{what} of {width}x{height} pixels: this adapter ({self.name}) allows 1 to {limit} "
                              "pixels per side")

    # -- buffers ------------------------------------------------------------------------------------
    def buffer(self, nbytes: int, label: str, usage: int = STORAGE) -> wgpu.GPUBuffer:
        """An uninitialised (zeroed by wgpu) buffer of at least 4 bytes; sizes round up to 4."""
        size = max(4, (int(nbytes) + 3) // 4 * 4)
        if size > int(self.device.limits["max-buffer-size"]):
            raise GpuMemoryError(f"buffer {label!r} needs {size} bytes, over the device's max-buffer-size; "
                                 "render fewer surfels or a smaller image")
        if usage & wgpu.BufferUsage.STORAGE and size > self.max_binding_bytes:
            raise GpuMemoryError(f"buffer {label!r} needs {size} bytes, over the adapter's storage binding limit of "
                              f"{self.max_binding_bytes} bytes; render fewer surfels or a smaller image")
        self.allocated_bytes += size
        return self.device.create_buffer(label=label, size=size, usage=usage)

    @property
    def recycler(self) -> BufferRecycler:
        """Buffers released by per-call objects, for reuse (see gma/gpu/recycle.py)."""
        if self._recycler is None:
            self._recycler = BufferRecycler(self)
        return self._recycler

    def upload(self, array: np.ndarray, label: str, usage: int = STORAGE) -> wgpu.GPUBuffer:
        """A new buffer holding ``array`` (C-contiguous copy made if needed); counted in transfers."""
        data = np.ascontiguousarray(array)
        buf = self.buffer(data.nbytes, label, usage)
        self.write(buf, data)
        return buf

    def constant(self, array: np.ndarray, label: str, usage: int = STORAGE) -> wgpu.GPUBuffer:
        """A buffer holding ``array``'s bytes that nobody writes again, shared by every caller asking for
        the same bytes and usage. Small per-call values (a scan's count, a render's background) then bind
        the same buffer call after call, so their bind groups are found in the cache instead of made again
        (gma/gpu/bind_groups.py), and no buffer is created or uploaded. Callers must never write to
        it. At most CONSTANT_CACHE_ENTRIES (least recently used go) of up to 4 KiB each."""
        data = np.ascontiguousarray(array)
        if data.nbytes > 4096:
            raise ValueError(f"constant {label!r}: {data.nbytes} bytes, over the 4 KiB of a cached constant")
        key = (int(usage), data.tobytes())
        with self._constants_lock:
            buf = self._constants.get(key)
            if buf is not None:
                self._constants.move_to_end(key)
                return buf
        buf = self.upload(data, label, usage)
        with self._constants_lock:
            buf = self._constants.setdefault(key, buf)
            while len(self._constants) > CONSTANT_CACHE_ENTRIES:
                self._constants.popitem(last=False)
        return buf

    def write(self, buffer: wgpu.GPUBuffer, array: np.ndarray, offset: int = 0) -> None:
        data = np.ascontiguousarray(array)
        if data.nbytes == 0:
            return
        with self.transfers.upload(data.nbytes):
            self.device.queue.write_buffer(buffer, offset, data)

    def read(self, buffer: wgpu.GPUBuffer, dtype, count: int | None = None, offset: int = 0) -> np.ndarray:
        """Copy ``count`` items of ``dtype`` back from ``buffer`` (waits for queued work)."""
        dtype = np.dtype(dtype)
        nbytes = (buffer.size - offset) if count is None else int(count) * dtype.itemsize
        if nbytes == 0:
            return np.zeros(0, dtype)
        with self.transfers.download(nbytes):
            raw = self.device.queue.read_buffer(buffer, offset, nbytes)
        return np.frombuffer(raw, dtype=dtype).copy()

    def read_many(self, items: list[tuple[wgpu.GPUBuffer, object, int]]) -> list[np.ndarray]:
        """Copy several buffers back in one transfer: ``items`` are (buffer, dtype, count). All copies go
        into one staging buffer with one submission and one map, instead of a wait per buffer."""
        sizes = [int(count) * np.dtype(dtype).itemsize for _, dtype, count in items]
        offsets = np.concatenate([[0], np.cumsum([(n + 3) // 4 * 4 for n in sizes])]).astype(int)
        total = int(offsets[-1])
        if total == 0:
            return [np.zeros(0, dtype) for _, dtype, _ in items]
        if self.transfers.wait_for_compute:   # so that the transfer timing counts the copy, not the compute
            self.wait_idle()
        with _staging_lock, self.transfers.download(total):
            # Kept and reused up to STAGING_KEEP_BYTES: a fresh multi-megabyte staging buffer per read costs
            # lavapipe an allocation, its page faults and wgpu's zero-fill.
            staging = getattr(self, "_staging", None)
            if staging is None or staging.size < total:
                staging = self.device.create_buffer(label="read_many", size=total,
                                                    usage=wgpu.BufferUsage.MAP_READ | wgpu.BufferUsage.COPY_DST)
                if total <= STAGING_KEEP_BYTES:
                    self._staging = staging
            enc = self.device.create_command_encoder()
            for (buf, _, _), off, n in zip(items, offsets, sizes):
                if n:
                    enc.copy_buffer_to_buffer(buf, 0, staging, int(off), (n + 3) // 4 * 4)
            self.device.queue.submit([enc.finish()])
            staging.map_sync(wgpu.MapMode.READ, 0, total)
            # One copy out of the mapping (read_mapped's default would make one more).
            raw = _copy_out(np.frombuffer(staging.read_mapped(0, total, copy=False), np.uint8))
            staging.unmap()
        return [raw[off:off + n].view(np.dtype(dtype)) for (_, dtype, _), off, n in zip(items, offsets, sizes)]

    def wait_idle(self) -> None:
        """Block until all submitted work has finished. (A 4-byte read of a fence buffer: wgpu-py 0.32's
        ``on_submitted_work_done_sync`` fails with a callback signature mismatch.)"""
        fence = getattr(self, "_fence", None)
        if fence is None:
            fence = self._fence = self.device.create_buffer(label="fence", size=4, usage=STORAGE)
        self.device.queue.read_buffer(fence, 0, 4)

    def submit(self, encoder: wgpu.GPUCommandEncoder) -> None:
        self.device.queue.submit([encoder.finish()])


HOST_MEMORY = HostMemoryPool()   # read-backs' host memory, reused once their arrays are gone
PARALLEL_COPY_BYTES = 2 << 20  # read_many copies larger reads out of the mapping on two threads
_copy_pool: ThreadPoolExecutor | None = None


def _copy_out(mapped: np.ndarray) -> np.ndarray:
    """A copy of ``mapped`` in reused host memory (gma/gpu/host_memory.py: fresh pages cost a fault
    each); a large one in two halves, one on a helper thread (numpy releases the GIL while copying). The
    device idles while the host copies a read back out of the mapping, so a second core is free."""
    global _copy_pool
    out = HOST_MEMORY.take(mapped.nbytes)
    if mapped.nbytes < PARALLEL_COPY_BYTES or (os.cpu_count() or 1) < 2:
        np.copyto(out, mapped)
        return out
    if _copy_pool is None:
        _copy_pool = ThreadPoolExecutor(1, thread_name_prefix="gma-copy")
    half = mapped.size // 2 // 4096 * 4096
    second = _copy_pool.submit(np.copyto, out[half:], mapped[half:])
    np.copyto(out[:half], mapped[:half])
    second.result()
    return out


_shared: GpuContext | None = None
_staging_lock = threading.Lock()  # read_many's staging buffer is reused: one read at a time
_shared_lock = threading.Lock()


def get_context() -> GpuContext:
    """The process-wide default context, created on first use (never at import)."""
    global _shared
    with _shared_lock:
        if _shared is None:
            _shared = GpuContext.create()
        return _shared
