// Block masks of the tile-sorted intersections, for the rasterizers' subgroup variant (CPU drivers):
// for intersection j (surfel isect_ids[j] in tile isect_tiles[j]) the 4x2 pixel blocks of the tile that
// the surfel can reach with alpha >= 1/255 (bit by * 4 + bx, block_bit in rasterize_core.wgsl), from the
// block bands projection wrote (write_bands in project_fwd.wgsl). One thread per intersection, once per
// render; the forward and backward rasterizers read the masks in list order. (They used to compute
// them per batch into workgroup memory, which needed barriers; see composite_quad.)
// Define RECORD_KEYS: the keys carry more than the tile id (emit_isects.wgsl).
#include "common/render_types.wgsl"

@group(0) @binding(0) var<storage, read> elem_info: DispatchInfo;
@group(0) @binding(1) var<storage, read> isect_tiles: array<u32>;        // tile-sorted keys
@group(0) @binding(2) var<storage, read> isect_ids: array<u32>;          // tile-sorted surfel ids
@group(0) @binding(3) var<storage, read> block_bands: array<vec2<u32>>;  // [N] see write_bands
@group(0) @binding(4) var<uniform> params: RenderParams;
@group(0) @binding(5) var<storage, read_write> isect_masks: array<u32>;  // [isects]

// The tile's block columns (bits 0-3, tile column `tcol` = x / 4 of its left edge) in band `band`
// (absolute 8-row band) of a surfel with block bands `w` (see write_bands in project_fwd.wgsl).
fn band_columns(w: vec2<u32>, band: u32, tcol: u32) -> u32 {
    let j = band - (w.x & 0x1fffu);   // wraps above the first band
    let nb = (w.x >> 13u) & 3u;
    let col0 = i32(w.x >> 15u) - i32(tcol);
    let bits = w.y >> (10u * min(j, 2u));
    let lo = max(col0 + select(i32(bits & 31u), 0, nb == 0u), 0);
    let hi = min(select(col0 + i32((bits >> 5u) & 31u), i32(w.y) - i32(tcol), nb == 0u), 3);
    let cols = ((2u << u32(max(hi, 0))) - 1u) & ~((1u << u32(min(lo, 3))) - 1u);
    return select(0u, cols, (nb == 0u || j < nb) && lo <= hi);
}

// Blocks of tile `tile` (see block_bit in rasterize_core.wgsl) where surfel `sid` can reach alpha >= 1/255 at some pixel centre:
// the columns of the tile's two 8-row bands (a subgroup's height, so a finer mask would list no fewer
// hits) that projection computed, each repeated over the band's four block rows. Strictly
// conservative (see block_shape in project_fwd.wgsl), so a subgroup that the surfel's box reaches but
// this mask does not sees only alpha < 1/255 from it, which the blend skips anyway: images and
// gradients are bit-identical to the box's. Standard scene (100k surfels, random orientations):
// subgroup hit candidates 669k with the box, 551k with bands for every surfel; lavapipe, same runs
// against the box, two each: forward rasterize -8 to -9 %, backward -6 to -7.5 %, projection +0.3 to
// +0.5 ms; avatar-like scene (small surfels, no fewer hits): forward -0.5 / +0.8 %, backward -2 / +3 %
// (noise). Tried: computing the ellipse's columns while staging (32 bytes per surfel read; standard
// -3 to -5 %, avatar +5 to +8 %); per-band words read from 64 or 16 bytes per surfel (standard -5 to
// -6 %, avatar +4 to +6 % and +2 to +4 %): the extra bytes per staged surfel miss the cache.
fn block_mask(sid: u32, tile: u32) -> u32 {
    let w = block_bands[sid];
    let band = (tile / params.tile_grid.x) * (TILE_SIZE / 8u);
    let tcol = (tile % params.tile_grid.x) * (TILE_SIZE / 4u);
    return (band_columns(w, band, tcol) | (band_columns(w, band + 1u, tcol) << 16u)) * 0x1111u;
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = gid.x;
    if j >= elem_info.count {
        return;
    }
#if RECORD_KEYS
    let tile = isect_tiles[j] & TILE_KEY_MASK;
#else
    let tile = isect_tiles[j];
#endif
    isect_masks[j] = block_mask(isect_ids[j], tile);
}
