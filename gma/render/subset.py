"""Thinned surfel sets: every ``stride``-th surfel with its scales enlarged, made on the GPU.

The viewer draws such a set while the camera moves or a motion plays on a slow adapter: the renderer's
cost grows with the number of surfels far more than with the image size (most surfels cover less than
a tile), so a quarter of the surfels makes a frame about three times cheaper. Each kept surfel covers
``stride`` times its area, so the body stays closed, only softer: the short axis grows first, up to the
long one, then both alike (growing both by ``sqrt(stride)`` turns long thin surfels into streaks).

Which surfels: the first ``N / stride`` of an *order* (:func:`spread_order`) in which every prefix is
spread over the surface: each face's first surfel (faces in random order), then each face's second, and
so on. Every ``stride``-th surfel by index would keep whole rows of faces and drop the next rows (face
ids follow the mesh's rows), which shows as stripes.
"""

from __future__ import annotations

import math

import numpy as np
import wgpu

from gma.gpu import GpuContext
from gma.render.surfels import SurfelBuffers

__all__ = ["SurfelSubset", "spread_order", "subset_count", "subset_reference"]

UNIFORM = wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST


def subset_count(count: int, stride: int) -> int:
    """Surfels kept from ``count`` at ``stride``: indices 0, stride, 2 stride, ..."""
    return (count + stride - 1) // stride


def spread_order(count: int, face_ids=None, seed: int = 0) -> np.ndarray:
    """[count] u32 surfel ids whose every prefix covers the surface evenly: each face's first surfel, in
    a random order of faces, then each face's second, ... ``face_ids`` [count]: the face each surfel is
    bound to (None: surfels without a mesh, in random order)."""
    rng = np.random.default_rng(seed)
    if face_ids is None:
        return rng.permutation(count).astype(np.uint32)
    face_ids = np.asarray(face_ids, np.int64).reshape(-1)
    if len(face_ids) != count:
        raise ValueError(f"face_ids holds {len(face_ids)} entries for {count} surfels")
    if count == 0:
        return np.zeros(0, np.uint32)
    by_face = np.argsort(face_ids, kind="stable")
    sorted_faces = face_ids[by_face]
    first = np.r_[0, np.nonzero(np.diff(sorted_faces))[0] + 1]  # where each face's run starts
    rank = np.empty(count, np.int64)
    rank[by_face] = np.arange(count) - np.repeat(first, np.diff(np.r_[first, count]))
    face_rank = rng.permutation(int(face_ids.max()) + 1)
    return np.lexsort((face_rank[face_ids], rank)).astype(np.uint32)


def subset_reference(arrays: dict[str, np.ndarray], stride: int, order: np.ndarray | None = None
                     ) -> dict[str, np.ndarray]:
    """The numpy twin of :meth:`SurfelSubset.encode` (tests compare against it)."""
    n = len(next(iter(arrays.values())))
    keep = order[:subset_count(n, stride)] if order is not None else np.arange(0, n, stride)
    out = {k: np.asarray(v)[keep].copy() for k, v in arrays.items()}
    s = out["scales"].astype(np.float32)
    f = np.float32(stride)
    short, long = s.min(1), s.max(1)
    grow_short = short * f <= long
    wide = np.where(grow_short[:, None], s * np.where(s[:, :1] < s[:, 1:], [f, 1], [1, f]).astype(np.float32),
                    (np.sqrt(short * long) * np.float32(math.sqrt(stride)))[:, None])
    out["scales"] = wide.astype(np.float32)
    return out


class SurfelSubset:
    """Keeps the output buffers of one source between frames; :meth:`encode` refreshes them."""

    def __init__(self, ctx: GpuContext):
        self.ctx = ctx
        self._params = ctx.buffer(16, "subset.params", UNIFORM)
        self._key: tuple | None = None
        self._out: SurfelBuffers | None = None
        self._order_key: object = None
        self._order: wgpu.GPUBuffer | None = None

    def encode(self, encoder, source: SurfelBuffers, stride: int, order: np.ndarray | None = None
               ) -> SurfelBuffers:
        """Record the copy of ``source``'s surfels ``order[:N / stride]`` (None: every ``stride``-th) into
        ``encoder``; returns the thinned buffers (valid once the encoder is submitted). ``stride`` 1
        returns ``source`` itself. ``order`` is uploaded once per array object (keep passing the same one)."""
        stride = int(stride)
        if stride < 1:
            raise ValueError(f"subset stride must be >= 1, got {stride}")
        if stride == 1 or source.count == 0:
            return source
        count = subset_count(source.count, stride)
        if order is None:
            order = np.arange(0, source.count, stride, dtype=np.uint32)
        if len(order) < count or (len(order) and int(order.max()) >= source.count):
            raise ValueError(f"subset order of {len(order)} ids does not fit {source.count} surfels")
        if order is not self._order_key:
            self._order = self.ctx.upload(np.ascontiguousarray(order, np.uint32), "subset.order")
            self._order_key = order
        key = (id(source), source.count, source.channels, stride)
        if key != self._key:
            self._out = SurfelBuffers.allocate(self.ctx, count, source.channels)
            self.ctx.write(self._params, np.array([count, stride, 0, 0], np.uint32))
            self.ctx.write(self._params, np.array([math.sqrt(stride)], np.float32), offset=8)
            self._key = key
        out = self._out
        pipeline = self.ctx.compute_pipeline("render/subset.wgsl", {"CHANNELS": source.channels})
        cp = encoder.begin_compute_pass()
        cp.set_pipeline(pipeline)
        cp.set_bind_group(0, self.ctx.bind_group(pipeline, [
            self._params, source.means, source.quats, source.scales, source.opacities, source.colors,
            out.means, out.quats, out.scales, out.opacities, out.colors, self._order]))
        cp.dispatch_workgroups((count + 255) // 256)
        cp.end()
        return out
