// Per-tile [start, end) ranges in the tile-sorted intersection list: one thread per tile, two binary
// searches (lower bounds of the tile and of the next one) over the `count` sorted tile ids. Every tile
// is written, empty ones as [x, x), so nothing needs clearing first; one thread per intersection
// comparing it with its neighbours would take a couple of hundred times as many threads.
// Define RECORD_KEYS: the keys carry more than the tile id (emit_isects.wgsl); only the tile id counts.
#include "common/render_types.wgsl"

@group(0) @binding(0) var<storage, read> elem_info: DispatchInfo;
@group(0) @binding(1) var<storage, read> isect_tiles: array<u32>;
@group(0) @binding(2) var<storage, read_write> ranges: array<vec2<u32>>;   // [num_tiles]
@group(0) @binding(3) var<uniform> params: RenderParams;

// First index in [0, count) whose tile id is >= tile (count when none).
fn lower_bound(tile: u32, count: u32) -> u32 {
    var lo = 0u;
    var hi = count;
    while lo < hi {
        let mid = (lo + hi) / 2u;
#if RECORD_KEYS
        let below = (isect_tiles[mid] & TILE_KEY_MASK) < tile;
#else
        let below = isect_tiles[mid] < tile;
#endif
        lo = select(lo, mid + 1u, below);
        hi = select(mid, hi, below);
    }
    return lo;
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let tile = gid.x;
    if tile >= params.tile_grid.x * params.tile_grid.y {
        return;
    }
    let count = elem_info.count;
    ranges[tile] = vec2<u32>(lower_bound(tile, count), lower_bound(tile + 1u, count));
}
