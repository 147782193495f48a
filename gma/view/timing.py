"""Frame statistics: frames per second from wall-clock time, and a per-pass GPU time breakdown from
timestamp queries sampled on one frame in ``every`` (reading the timestamps back is a sync point, so
the frame loop must not do it each frame)."""

from __future__ import annotations

import time
from collections import deque

import numpy as np

from gma.gpu import GpuContext, PassTimer

__all__ = ["FrameStats", "FrameTimer"]

# Pass names of the renderer and the viewer, grouped for display.
_GROUPS = {"project": "project", "sort": "sort", "bin": "bin", "rasterize": "rasterize", "overlay": "overlay",
           "pose": "pose"}


class FrameTimer(PassTimer):
    """A :class:`PassTimer` that also measures work it cannot wrap, such as ``GpuPoser``'s own compute
    pass: :meth:`mark` records an empty timestamped pass, and the span between two marks is timed."""

    def mark(self, encoder, name: str) -> None:
        w = self.writes(name)
        if w is not None:
            encoder.begin_compute_pass(timestamp_writes=w).end()

    def breakdown(self) -> dict[str, float]:
        """Milliseconds per pass group; the span from mark ``X.begin`` to mark ``X.end`` counts as ``X``."""
        if not self.enabled or not self.names:
            return {}
        raw = self.ctx.read(self.resolve_buf, np.uint64, 2 * len(self.names)).reshape(-1, 2).astype(np.int64)
        out: dict[str, float] = {}
        begins: dict[str, int] = {}
        for name, (t0, t1) in zip(self.names, raw):
            if name.endswith(".begin"):
                begins[name[:-6]] = int(t1)
                continue
            if name.endswith(".end"):
                base = name[:-4]
                ms = max(0, int(t0) - begins.pop(base, int(t0))) * 1e-6
            else:
                base, ms = name, max(0, int(t1) - int(t0)) * 1e-6
            group = _GROUPS.get(base, base)
            out[group] = out.get(group, 0.0) + ms
        self.names = []
        return out


class FrameStats:
    """Rolling FPS over the last ``window`` frames and the latest sampled GPU breakdown (ms per pass)."""

    def __init__(self, ctx: GpuContext, every: int = 30, window: int = 60):
        self.ctx = ctx
        self.every = max(1, every)
        self.frame = 0
        self._times: deque[float] = deque(maxlen=window)
        self._last: float | None = None
        self.gpu_ms: dict[str, float] = {}
        self._timer = FrameTimer(ctx, max_passes=256) if ctx.has_timestamps else None
        self._pending = False

    def timer_for_frame(self) -> FrameTimer | None:
        """The timer to pass to this frame's passes (None on unsampled frames or without timestamps)."""
        if self._timer is not None and self.frame % self.every == 0:
            self._pending = True
            return self._timer
        return None

    def end_frame(self) -> None:
        """Call after submitting a frame: updates FPS and, on sampled frames, reads the timestamps."""
        now = time.perf_counter()
        if self._last is not None:
            self._times.append(now - self._last)
        self._last = now
        if self._pending:
            self.gpu_ms = self._timer.breakdown()
            self._pending = False
        self.frame += 1

    @property
    def fps(self) -> float:
        return len(self._times) / sum(self._times) if self._times else 0.0

    @property
    def frame_ms(self) -> float:
        return 1e3 / self.fps if self.fps else 0.0

    def summary(self) -> str:
        parts = " ".join(f"{k} {v:.1f}" for k, v in self.gpu_ms.items())
        return f"{self.fps:5.1f} FPS ({self.frame_ms:.1f} ms)" + (f" | GPU ms: {parts}" if parts else "")
