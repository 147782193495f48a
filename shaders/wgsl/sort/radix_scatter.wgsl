// Radix sort, pass 3 of 3: stable scatter of keys and values to their digit's place. Within a block,
// a key's rank is (keys of the same digit owned by earlier threads) + (earlier keys of the same thread).
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;
@group(0) @binding(1) var<storage, read> hist: array<u32>;       // scanned: output offsets
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> vals_out: array<u32>;

var<workgroup> offsets: array<u32, 2048>;   // [RADIX][SORT_WG]: per digit, per thread

@compute @workgroup_size(SORT_WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let count = info.count;
    let block = wg.x;
    let start = block * SORT_BLOCK + lid * SORT_ITEMS;
    var local: array<u32, RADIX>;
    for (var i = 0u; i < SORT_ITEMS; i++) {
        let idx = start + i;
        if idx < count {
            local[(keys_in[idx] >> SHIFT) & (RADIX - 1u)] += 1u;
        }
    }
    for (var d = 0u; d < RADIX; d++) {
        offsets[d * SORT_WG + lid] = local[d];
    }
    workgroupBarrier();
    if lid < RADIX {
        // Thread `lid` turns digit lid's per-thread counts into global output positions.
        var run = hist[lid * info.groups_x + block];
        for (var t = 0u; t < SORT_WG; t++) {
            let c = offsets[lid * SORT_WG + t];
            offsets[lid * SORT_WG + t] = run;
            run += c;
        }
    }
    workgroupBarrier();
    for (var d = 0u; d < RADIX; d++) {
        local[d] = offsets[d * SORT_WG + lid];
    }
    for (var i = 0u; i < SORT_ITEMS; i++) {
        let idx = start + i;
        if idx < count {
            let key = keys_in[idx];
            let digit = (key >> SHIFT) & (RADIX - 1u);
            let pos = local[digit];
            local[digit] = pos + 1u;
            keys_out[pos] = key;
            vals_out[pos] = vals_in[idx];
        }
    }
}
