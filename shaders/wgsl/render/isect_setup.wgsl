// After the scan of tile counts: total intersections, clamped to the buffers' capacity, become the
// indirect dispatch sizes of the intersection sort and of the tile-range pass.
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"
#include "common/math.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> offsets: array<u32>;       // [N] exclusive scan, depth order
@group(0) @binding(2) var<storage, read> tile_counts: array<u32>;   // [N] by surfel id
@group(0) @binding(3) var<storage, read> sorted_ids: array<u32>;    // [N] depth order
@group(0) @binding(4) var<storage, read_write> sort_info: DispatchInfo;
@group(0) @binding(5) var<storage, read_write> elem_info: DispatchInfo;
@group(0) @binding(6) var<storage, read_write> stats: array<u32>;   // [0] wanted intersections

@compute @workgroup_size(1)
fn main() {
    let n = params.num_surfels;
    var total = 0u;
    if n > 0u {
        total = offsets[n - 1u] + tile_counts[sorted_ids[n - 1u]];
    }
    stats[0] = total;
    let count = min(total, params.isect_capacity);
    sort_info = DispatchInfo(ceil_div(count, SORT_BLOCK), 1u, 1u, count);
    elem_info = DispatchInfo(ceil_div(count, 256u), 1u, 1u, count);
}
