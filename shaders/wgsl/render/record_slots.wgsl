// Where each surfel's gradient records lie (GRAD_RECORDS in rasterize_bwd.wgsl): one thread per
// intersection of the tile-sorted list. Its key carries its number k within its surfel's list
// (RECORD_KEYS in emit_isects.wgsl), so its emission index is record_base[surfel] + k, and
// slots[emission index] = its place in the sorted list, where its record is. A surfel's emission
// indices are consecutive, so project_bwd.wgsl finds its records from record_base and its tile count.
// (Writing the records at their emission index instead, looked up while staging, made the rasterizer
// backward ~12 ms slower on the standard scene, more than this pass and the scattered reads cost.)
#include "common/render_types.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;             // isect_capacity = the list's length
@group(0) @binding(1) var<storage, read> isect_keys: array<u32>;     // tile-sorted keys
@group(0) @binding(2) var<storage, read> isect_ids: array<u32>;      // tile-sorted (SURFEL_ID_MASK: the id)
@group(0) @binding(3) var<storage, read> record_base: array<u32>;    // [N] by surfel id
@group(0) @binding(4) var<storage, read_write> slots: array<u32>;    // [isects] by emission index

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = gid.x;
    if j >= params.isect_capacity {
        return;
    }
    let e = record_base[isect_ids[j] & SURFEL_ID_MASK] + (isect_keys[j] >> RECORD_KEY_SHIFT);
    if e < params.isect_capacity {
        slots[e] = j;
    }
}
