// Intersection emission: thread i handles the i-th surfel in depth order and writes one (tile, surfel)
// pair per tile of its rectangle at its scanned offset. Emitting in depth order means a stable sort by
// tile alone leaves each tile's list sorted front to back.
#include "common/render_types.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> sorted_ids: array<u32>;    // [N] depth order
@group(0) @binding(2) var<storage, read> offsets: array<u32>;       // [N] depth order
@group(0) @binding(3) var<storage, read> tile_counts: array<u32>;   // [N] by surfel id
@group(0) @binding(4) var<storage, read> tile_rects: array<vec4<u32>>;
@group(0) @binding(5) var<storage, read_write> isect_tiles: array<u32>;
@group(0) @binding(6) var<storage, read_write> isect_ids: array<u32>;

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
    let rect = tile_rects[sid];
    var out = offsets[i];
    let cap = params.isect_capacity;
    for (var ty = rect.y; ty <= rect.w; ty++) {
        for (var tx = rect.x; tx <= rect.z; tx++) {
            if out >= cap {
                return;
            }
            isect_tiles[out] = ty * params.tile_grid.x + tx;
            isect_ids[out] = sid;
            out++;
        }
    }
}
