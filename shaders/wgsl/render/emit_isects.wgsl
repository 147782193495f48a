// Intersection emission: thread i handles the i-th surfel in depth order and writes one (tile, surfel)
// pair per tile of its rectangle at its scanned offset. Emitting in depth order means a stable sort by
// tile alone leaves each tile's list sorted front to back. A surfel is listed in the tiles of its box
// rectangle that its footprint reaches (tile_list in project_fwd.wgsl).
// Define RECORD_KEYS (a render whose backward sums per-intersection gradient records, see
// rasterize_bwd.wgsl): each key also carries, from bit RECORD_KEY_SHIFT, the intersection's number k
// within its surfel's list, and the surfel's first list index goes to record_base, so that the
// intersection's emission index, record_base[surfel] + k, is known after the tile sort too.
// Define BLOCK_BITS (the rasterizers' subgroup variant, CPU drivers): each surfel id carries,
// from bit SURFEL_ID_BITS, the tile's blocks the surfel can reach (tile_block_bits in block_bits.wgsl),
// and the subgroup steps through its lanes' rectangles together (see that main below).
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

// Whether tile t of a surfel's rectangle (tile_list's `tiles`, first tile `lo`) lists it.
fn listed_in(tiles: vec4<u32>, lo: vec2<u32>, t: vec2<u32>) -> bool {
    return tiles.w != 0u || ((tiles.z >> ((t.y - lo.y) * 16u + t.x - lo.x)) & 1u) != 0u;
}

// The sort key of the surfel's intersection number `number` (from 0) in tile t.
fn isect_key(t: vec2<u32>, number: u32) -> u32 {
#if RECORD_KEYS
    return (t.y * params.tile_grid.x + t.x) | (number << RECORD_KEY_SHIFT);
#else
    return t.y * params.tile_grid.x + t.x;
#endif
}

#if BLOCK_BITS
// The CPU drivers' variant (BLOCK_BITS): the subgroup steps through its lanes' tile
// rectangles together, one tile of each per step, as many steps as the largest rectangle (uniform), and
// every lane stores in every step: a tile that is not listed, past the lane's rectangle or past the
// capacity goes to the spare entry at isect_capacity, which nothing reads. Lavapipe makes each store a
// loop over the lanes, with a branch per lane when the store sits under a divergent condition (the
// nested loops over each lane's own rectangle and its skips); here there is none. The block bits take
// the tile's column and row (no integer division: lavapipe divides lane by lane).
#if WORK_QUEUE
@group(0) @binding(9) var<storage, read_write> work_queue: array<atomic<u32>>;
#endif
#include "common/surfel_pass_main.wgsl"

// Lists the intersections of the surfel at depth-order place i (none past the end; every lane of the
// subgroup calls it, for the subgroup reduction).
fn surfel_work(i: u32) {
    let valid = i < params.num_surfels;
    let j = min(i, params.num_surfels - 1u);   // lanes past the end read the last surfel and store nothing
    let sid = sorted_ids[j];
    let count = select(0u, tile_counts[sid], valid);
    let tiles = tile_rects[sid];
    let lo = vec2<u32>(tiles.x & 0xffffu, tiles.x >> 16u);
    let hi = vec2<u32>(tiles.y & 0xffffu, tiles.y >> 16u);
    let area = select(0u, (hi.x - lo.x + 1u) * (hi.y - lo.y + 1u), count != 0u);
    let first = select(0u, offsets[j], valid);
#if RECORD_KEYS
    if count != 0u {
        record_base[sid] = first;
    }
#endif
    let cap = params.isect_capacity;
    let bands = block_bands[sid];
    // Over the subgroup as it runs, whatever its size (a loop over the lanes on lavapipe, once per surfel).
    let trips = subgroupBroadcast(subgroupMax(area), 0u);
    var out = first;
    var t = lo;   // this step's tile
    for (var k = 0u; k < trips; k++) {
        let listed = k < area && listed_in(tiles, lo, t);
        let at = select(cap, out, listed && out < cap);
        isect_tiles[at] = isect_key(t, out - first);
        isect_ids[at] = sid | (tile_block_bits(bands, t.x, t.y) << SURFEL_ID_BITS);
        out += u32(listed);
        let wrap = t.x >= hi.x;
        t = vec2<u32>(select(t.x + 1u, lo.x, wrap), t.y + u32(wrap));
    }
}
#else
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
    for (var ty = lo.y; ty <= hi.y; ty++) {
        for (var tx = lo.x; tx <= hi.x; tx++) {
            if !listed_in(tiles, lo, vec2<u32>(tx, ty)) {
                continue;
            }
            if out >= cap {
                return;
            }
            isect_tiles[out] = isect_key(vec2<u32>(tx, ty), out - first);
            isect_ids[out] = sid;
            out++;
        }
    }
}
#endif
