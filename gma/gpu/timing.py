"""Per-pass GPU timing with timestamp queries, or wall-clock timing per submitted pass without them."""

from __future__ import annotations

import time

import numpy as np
import wgpu


class PassTimer:
    """Collects (name, milliseconds) for compute passes.

    With the ``timestamp-query`` feature each pass gets begin/end timestamps written by the GPU and
    :meth:`results` resolves them after the work is done. Without it, a pass's time is not available
    per pass; callers then time whole submissions on the CPU (see ``benchmarks/``).
    """

    def __init__(self, ctx, max_passes: int = 64):
        self.ctx = ctx
        self.enabled = ctx.has_timestamps
        self.names: list[str] = []
        self.max_passes = max_passes
        if self.enabled:
            self.query_set = ctx.device.create_query_set(type=wgpu.QueryType.timestamp, count=2 * max_passes)
            self.resolve_buf = ctx.buffer(16 * max_passes, "timestamps",
                                          wgpu.BufferUsage.QUERY_RESOLVE | wgpu.BufferUsage.COPY_SRC)

    def writes(self, name: str) -> dict | None:
        """``timestamp_writes`` argument for ``begin_compute_pass`` (None when disabled or full)."""
        if not self.enabled or len(self.names) >= self.max_passes:
            return None
        i = len(self.names)
        self.names.append(name)
        return {"query_set": self.query_set, "beginning_of_pass_write_index": 2 * i,
                "end_of_pass_write_index": 2 * i + 1}

    def resolve(self, encoder: wgpu.GPUCommandEncoder) -> None:
        if self.enabled and self.names:
            encoder.resolve_query_set(self.query_set, 0, 2 * len(self.names), self.resolve_buf, 0)

    def results(self) -> dict[str, float]:
        """Milliseconds per pass name (summed over passes sharing a name)."""
        out: dict[str, float] = {}
        for name, t0, t1 in self.intervals():
            out[name] = out.get(name, 0.0) + max(0, t1 - t0) * 1e-6
        return out

    def intervals(self) -> list[tuple[str, int, int]]:
        """(name, begin, end) of every pass in submission order, as raw timestamps (nanoseconds of the
        device's clock; on lavapipe the CPU's monotonic clock, so they line up with a profiler's samples:
        benchmarks/lavapipe_profile.py). Like :meth:`results`, starts a new collection."""
        if not self.enabled or not self.names:
            return []
        raw = self.ctx.read(self.resolve_buf, np.uint64, 2 * len(self.names)).reshape(-1, 2)
        out = [(name, int(t0), int(t1)) for name, (t0, t1) in zip(self.names, raw)]
        self.names = []
        return out


class WallClock:
    """Minimal stopwatch for benchmarks: ``with WallClock() as w: ...; w.ms``."""

    def __enter__(self):
        self.t0 = time.perf_counter()
        return self

    def __exit__(self, *exc):
        self.ms = (time.perf_counter() - self.t0) * 1e3
