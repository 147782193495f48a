// Radix sort, pass 1 of 3: per-block histogram of the digit at SHIFT (a define).
// hist is digit-major, hist[digit * num_blocks + block], so that one exclusive scan over it yields
// every block's output offset for every digit.
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"
#include "sort/radix_digits.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;   // groups_x = num_blocks, count = keys
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> hist: array<u32>;
#if KEY_BASE
@group(0) @binding(3) var<storage, read> key_base: array<u32>;   // see key_offset
#endif

// Each thread's count per digit; after the barrier thread d sums digit d's. (Not workgroup atomics:
// lavapipe runs each as a loop over the lanes with a locked compare-exchange per lane.)
var<workgroup> thread_counts: array<u32, RADIX * SORT_WG>;   // [RADIX][SORT_WG]

@compute @workgroup_size(SORT_WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let count = info.count;
    let block = wg.x;
    let start = block * SORT_BLOCK + lid * SORT_ITEMS;
    let base = key_offset();
    var counts = vec4<u32>(0u);   // per digit (radix_digits.wgsl)
    for (var i = 0u; i < SORT_ITEMS; i += 2u) {
        var c = counts;
        count_key(&c, start + i, count, base);
        count_key(&c, start + i + 1u, count, base);
        counts = c;
    }
    for (var d = 0u; d < RADIX; d++) {
        thread_counts[d * SORT_WG + lid] = digit_count(counts, d);
    }
    workgroupBarrier();
    if lid < RADIX {
        var total = 0u;
        for (var t = 0u; t < SORT_WG; t++) {
            total += thread_counts[lid * SORT_WG + t];
        }
        hist[lid * info.groups_x + block] = total;
    }
}

fn count_key(c: ptr<function, vec4<u32>>, idx: u32, count: u32, base: u32) {
    if idx < count {
        add_digit(c, key_digit(keys[idx], base));
    }
}
