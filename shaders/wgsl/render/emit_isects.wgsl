// Intersection emission: thread i handles the i-th surfel in depth order and writes one (tile, surfel)
// pair per tile of its rectangle at its scanned offset. Emitting in depth order means a stable sort by
// tile alone leaves each tile's list sorted front to back. A surfel is listed in the tiles of its box
// rectangle that its footprint reaches (tile_list in project_fwd.wgsl).
// Define RECORD_KEYS (a render whose backward sums per-intersection gradient records, see
// rasterize_bwd.wgsl): each key also carries, from bit RECORD_KEY_SHIFT, the intersection's number k
// within its surfel's list, and the surfel's first list index goes to record_base, so that the
// intersection's emission index, record_base[surfel] + k, is known after the tile sort too.
// Define BLOCK_BITS (the rasterizers' subgroup variant): each surfel id carries, from bit SURFEL_ID_BITS,
// the tile's blocks the surfel can reach (tile_block_bits in block_bits.wgsl).
#include "common/render_types.wgsl"
#include "render/block_bits.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> sorted_ids: array<u32>;    // [N] depth order
@group(0) @binding(2) var<storage, read> offsets: array<u32>;       // [N] depth order
@group(0) @binding(3) var<storage, read> tile_counts: array<u32>;   // [N] by surfel id
@group(0) @binding(4) var<storage, read> tile_rects: array<vec4<u32>>;   // [N] see tile_list
@group(0) @binding(5) var<storage, read_write> isect_tiles: array<u32>;
@group(0) @binding(6) var<storage, read_write> isect_ids: array<u32>;
#if RECORD_KEYS
@group(0) @binding(7) var<storage, read_write> record_base: array<u32>;   // [N] by surfel id
#endif
#if BLOCK_BITS
@group(0) @binding(8) var<storage, read> block_bands: array<vec2<u32>>;   // [N] see write_bands
#endif

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    if i >= params.num_surfels {
        return;
    }
    let sid = sorted_ids[i];
    if tile_counts[sid] == 0u {
        return;
    }
    let tiles = tile_rects[sid];
    let lo = vec2<u32>(tiles.x & 0xffffu, tiles.x >> 16u);
    let hi = vec2<u32>(tiles.y & 0xffffu, tiles.y >> 16u);
    let first = offsets[i];
    var out = first;
#if RECORD_KEYS
    record_base[sid] = first;
#endif
    let cap = params.isect_capacity;
#if BLOCK_BITS
    let bands = block_bands[sid];
#endif
    for (var ty = lo.y; ty <= hi.y; ty++) {
        for (var tx = lo.x; tx <= hi.x; tx++) {
            if tiles.w == 0u && ((tiles.z >> ((ty - lo.y) * 16u + tx - lo.x)) & 1u) == 0u {
                continue;
            }
            if out >= cap {
                return;
            }
#if RECORD_KEYS
            isect_tiles[out] = (ty * params.tile_grid.x + tx) | ((out - first) << RECORD_KEY_SHIFT);
#else
            isect_tiles[out] = ty * params.tile_grid.x + tx;
#endif
#if BLOCK_BITS
            let tile_id = ty * params.tile_grid.x + tx;
            isect_ids[out] = sid | (tile_block_bits(bands, tile_id, params.tile_grid.x) << SURFEL_ID_BITS);
#else
            isect_ids[out] = sid;
#endif
            out++;
        }
    }
}
