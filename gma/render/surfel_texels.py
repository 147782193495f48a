"""The projected surfels and their colours as textures, for the tile walks' gathers (lavapipe).

Per group of 8 intersections each lane of a tile walk (tile_walk_fwd.wgsl, tile_walk_bwd.wgsl) reads one
surfel's projection (four vec4s) and colour (one vec4) at an index of its own. Lavapipe turns a storage
buffer read at a lane-varying index into a loop over the lanes with a bounds check and a branch per lane
and component, whereas it fetches a texel of a storage texture for all lanes at once: a vec4 gather from
a 16 MB table, sequential per lane, ran 2.0-2.3x faster from an rgba32float storage texture than from an
array<vec4<f32>> (random indices: 2.6x), where scalar reads gained nothing (r32float). Standard scene,
100k surfels, both in one process, 10-12 rounds: forward rasterize 0.82-0.85x, backward rasterize
0.86-0.89x, images and gradients bit-identical.

Projection keeps writing the buffers (the backward, other variants and GPUs read those); each rasterizer
pass first copies them into these textures (a memcpy on lavapipe: ~0.5 ms for 100k surfels). So the
textures are scratch of one pass: a backward copies again from its forward state's buffers, and renders
in between cannot disturb it (the queue runs copies and passes in order).
"""

from __future__ import annotations

import wgpu

# Texels per row: 1024 surfels of 4 texels (t0, t1, t2, normal_depth), or 4096 colours. The tile walks
# address them with the same constants (surfel_texels.wgsl).
TEXEL_ROW = 4096
PROJECTED_TEXELS = 4
COLOR_TEXELS = 1
PROJECTED_BINDING, COLORS_BINDING = 20, 21   # replace the buffers at 1 (projected) and 15 (colors4)


class SurfelTexels:
    """Grow-only textures holding the first surfels' projections and colours for one rasterizer pass."""

    def __init__(self, ctx):
        self.ctx = ctx
        self.max_rows = int(ctx.limits["max-texture-dimension-2d"])
        # Surfels that fit (the colours' texture is 4x shorter); 0 where a row does not fit.
        self.capacity = self.max_rows * (TEXEL_ROW // PROJECTED_TEXELS) if TEXEL_ROW <= self.max_rows else 0
        self._textures: dict[int, wgpu.GPUTexture] = {}

    def bind(self, encoder, resources: dict, projected: wgpu.GPUBuffer, colors4: wgpu.GPUBuffer, n: int) -> None:
        """Encode the copies of ``n`` surfels' projections and colours into the textures and bind them in
        ``resources`` in place of the buffers (whose bindings the texel variant does not declare)."""
        views = [self._copy(encoder, buf, per_item, n) for buf, per_item in
                 ((projected, PROJECTED_TEXELS), (colors4, COLOR_TEXELS))]
        del resources[1], resources[15]
        resources[PROJECTED_BINDING], resources[COLORS_BINDING] = views

    def _copy(self, encoder, buf: wgpu.GPUBuffer, per_item: int, n: int) -> wgpu.GPUTextureView:
        per_row = TEXEL_ROW // per_item
        rows = -(-n // per_row)
        tex = self._texture(per_item, rows)
        full = n // per_row
        row_bytes = 16 * TEXEL_ROW
        if full:
            encoder.copy_buffer_to_texture({"buffer": buf, "offset": 0, "bytes_per_row": row_bytes,
                                            "rows_per_image": full}, {"texture": tex}, (TEXEL_ROW, full, 1))
        rest = n - full * per_row
        if rest:   # the last, partial row
            encoder.copy_buffer_to_texture({"buffer": buf, "offset": full * row_bytes, "bytes_per_row": row_bytes},
                                           {"texture": tex, "origin": (0, full, 0)}, (rest * per_item, 1, 1))
        return tex.create_view()

    def _texture(self, per_item: int, rows: int) -> wgpu.GPUTexture:
        tex = self._textures.get(per_item)
        if tex is None or tex.size[1] < rows:
            grown = rows if tex is None else min(self.max_rows, max(rows, tex.size[1] * 5 // 4))
            tex = self._textures[per_item] = self.ctx.device.create_texture(
                label=f"surfel_texels.{per_item}", size=(TEXEL_ROW, grown, 1),
                format=wgpu.TextureFormat.rgba32float,
                usage=wgpu.TextureUsage.COPY_DST | wgpu.TextureUsage.STORAGE_BINDING)
        return tex
