"""The projected surfels and their colours as textures, for the tile walks' gathers (lavapipe).

Per group of 8 intersections each lane of a tile walk (tile_walk_fwd.wgsl, tile_walk_bwd.wgsl) reads one
surfel's projection and colour (five vec4s; the backward four) at an index of its own. The tile walks'
projection writes them in its own layout (WALK_LAYOUT in project_fwd.wgsl; surfel_texels.wgsl): the
``projected`` buffer's four vec4s per surfel are its ray plane (the ray transform in the form the
rasterizers evaluate, ray_plane.wgsl) and its colour, the ``colors4`` buffer's vec4
its normal and depth, so that the backward walk reads one cache line per surfel. Lavapipe turns a storage
buffer read at a lane-varying index into a loop over the lanes with a bounds check and a branch per lane
and component, whereas it fetches a texel of a storage texture for all lanes at once, so vec4 gathers
are much cheaper from an rgba32float storage texture than from an array<vec4<f32>> (scalar reads gain
nothing: r32float). Images and gradients are bit-identical either way.

Projection keeps writing the buffers (the backward, other variants and GPUs read those); each rasterizer
pass first copies them into textures (a memcpy on lavapipe, small against the pass).
A render the backward will replay copies into textures leased to its state (TexelLease), which its
backward binds as they are; other renders copy into scratch textures of one pass (the queue runs copies
and passes in order, so renders in between cannot disturb a pass). The backward's tile walk
writes its gradient records straight into such a texture, which project_bwd reads (scattered reads, in
tile order): faster than from a buffer, and a copy of that buffer into a texture costs more than the
faster reads of a freshly copied texture save.
"""

from __future__ import annotations

import threading
from dataclasses import dataclass

import wgpu

# Texels per row: 1024 surfels of 4 texels (t0, t1, t2, colour), or 4096 of colors4's vec4s (normal and
# depth in the tile walks' layout). The shaders
# address them with the same constant (texel_at in common/render_types.wgsl).
TEXEL_ROW = 4096
PROJECTED_TEXELS = 4
COLOR_TEXELS = 1
PROJECTED_BINDING, COLORS_BINDING = 20, 21   # replace the buffers at 1 (projected) and 15 (colors4)


@dataclass
class TexelLease:
    """Textures holding one forward render's surfel projections and colours (views included), for its
    backward to bind without copying again; given back when the render's state is collected."""

    projected: tuple[wgpu.GPUTexture, wgpu.GPUTextureView]
    colors: tuple[wgpu.GPUTexture, wgpu.GPUTextureView]
    surfels: int   # how many surfels they hold at most


KEEP_LEASES = 4   # given-back leases kept for reuse (a training loop holds one state at a time)


class SurfelTexels:
    """Grow-only rgba32float textures holding copies of vec4 buffers for one pass: texel t of a copy at
    (t % TEXEL_ROW, t // TEXEL_ROW), so that a surfel's projection row k is texel 4 i + k."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.max_rows = int(ctx.limits["max-texture-dimension-2d"])
        # Texels a copy can hold (0 where a row does not fit), and surfels whose projections fit.
        self.max_texels = self.max_rows * TEXEL_ROW if TEXEL_ROW <= self.max_rows else 0
        self.capacity = self.max_texels // PROJECTED_TEXELS
        # name -> (texture, its view): one view per texture, so that bind groups with it are reused
        # (making a view, and a bind group with a fresh view, costs lavapipe time on every call).
        self._textures: dict[str, tuple[wgpu.GPUTexture, wgpu.GPUTextureView]] = {}
        # Leases given back (give_back may run inside garbage collection, on any thread: it only appends).
        self._free_leases: list[TexelLease] = []
        self._lock = threading.Lock()

    def bind(self, encoder, resources: dict, projected: wgpu.GPUBuffer, colors4: wgpu.GPUBuffer, n: int,
             lease: bool = False) -> TexelLease | None:
        """Encode the copies of ``n`` surfels' projections and colours into textures and bind them in
        ``resources`` in place of the buffers (whose bindings the texel variant does not declare). With
        ``lease`` the textures are the caller's until it gives them back (returned; see bind_lease)."""
        if not lease:
            del resources[1], resources[15]
            resources[PROJECTED_BINDING] = self.copy(encoder, "projected", projected, PROJECTED_TEXELS * n)
            resources[COLORS_BINDING] = self.copy(encoder, "colors", colors4, COLOR_TEXELS * n)
            return None
        held = self._take_lease(n)
        _copy_into(encoder, held.projected[0], projected, PROJECTED_TEXELS * n)
        _copy_into(encoder, held.colors[0], colors4, COLOR_TEXELS * n)
        self.bind_lease(resources, held)
        return held

    @staticmethod
    def bind_lease(resources: dict, held: TexelLease) -> None:
        """Bind a lease's textures as they are, in place of the buffers."""
        del resources[1], resources[15]
        resources[PROJECTED_BINDING], resources[COLORS_BINDING] = held.projected[1], held.colors[1]

    def give_back(self, held: TexelLease) -> None:
        """Return a lease for later renders (nothing may bind it any more)."""
        self._free_leases.append(held)   # list.append: atomic, takes no lock

    def _take_lease(self, n: int) -> TexelLease:
        with self._lock:
            while len(self._free_leases) > KEEP_LEASES:
                self._free_leases.pop(0)
            for i, held in enumerate(self._free_leases):
                if held.surfels >= n:
                    return self._free_leases.pop(i)
        rows = min(self.max_rows, max(1, _rows_for(PROJECTED_TEXELS * -(-5 * n // 4))))   # 25 % to grow into
        surfels = rows * (TEXEL_ROW // PROJECTED_TEXELS)
        return TexelLease(self._new_texture("lease.projected", rows),
                          self._new_texture("lease.colors", _rows_for(COLOR_TEXELS * surfels)), surfels)

    def view(self, name: str, texels: int) -> wgpu.GPUTextureView:
        """Texture ``name`` holding at least ``texels`` (at most ``max_texels``), for a pass to write."""
        return self._texture(name, _rows_for(texels))[1]

    def copy(self, encoder, name: str, buf: wgpu.GPUBuffer, texels: int) -> wgpu.GPUTextureView:
        """Encode a copy of the first ``texels`` vec4s of ``buf`` into texture ``name`` (at most
        ``max_texels``), and return its view."""
        tex, view = self._texture(name, _rows_for(texels))
        _copy_into(encoder, tex, buf, texels)
        return view

    def _texture(self, name: str, rows: int) -> tuple[wgpu.GPUTexture, wgpu.GPUTextureView]:
        held = self._textures.get(name)
        if held is None or held[0].size[1] < rows:
            grown = rows if held is None else min(self.max_rows, max(rows, held[0].size[1] * 5 // 4))
            held = self._textures[name] = self._new_texture(name, grown)
        return held

    def _new_texture(self, name: str, rows: int) -> tuple[wgpu.GPUTexture, wgpu.GPUTextureView]:
        tex = self.ctx.device.create_texture(
            label=f"texels.{name}", size=(TEXEL_ROW, rows, 1), format=wgpu.TextureFormat.rgba32float,
            usage=wgpu.TextureUsage.COPY_DST | wgpu.TextureUsage.STORAGE_BINDING)
        return tex, tex.create_view()


def _rows_for(texels: int) -> int:
    """Texture rows that hold ``texels`` vec4s."""
    return -(-texels // TEXEL_ROW)


def _copy_into(encoder, tex: wgpu.GPUTexture, buf: wgpu.GPUBuffer, texels: int) -> None:
    """Encode a copy of the first ``texels`` vec4s of ``buf`` into ``tex`` (texel t at (t % TEXEL_ROW,
    t // TEXEL_ROW))."""
    full, rest = divmod(texels, TEXEL_ROW)
    row_bytes = 16 * TEXEL_ROW
    if full:
        encoder.copy_buffer_to_texture({"buffer": buf, "offset": 0, "bytes_per_row": row_bytes,
                                        "rows_per_image": full}, {"texture": tex}, (TEXEL_ROW, full, 1))
    if rest:   # the last, partial row
        encoder.copy_buffer_to_texture({"buffer": buf, "offset": full * row_bytes, "bytes_per_row": row_bytes},
                                       {"texture": tex, "origin": (0, full, 0)}, (rest, 1, 1))
