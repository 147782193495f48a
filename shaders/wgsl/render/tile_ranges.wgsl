// Per-tile [start, end) ranges in the tile-sorted intersection list (ranges must be zeroed first).
#include "common/render_types.wgsl"

@group(0) @binding(0) var<storage, read> elem_info: DispatchInfo;
@group(0) @binding(1) var<storage, read> isect_tiles: array<u32>;
@group(0) @binding(2) var<storage, read_write> ranges: array<vec2<u32>>;   // [num_tiles]

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.x;
    let n = elem_info.count;
    if i >= n {
        return;
    }
    let tile = isect_tiles[i];
    if i == 0u || isect_tiles[i - 1u] != tile {
        ranges[tile].x = i;
    }
    if i + 1u == n || isect_tiles[i + 1u] != tile {
        ranges[tile].y = i + 1u;
    }
}
