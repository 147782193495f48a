// Lane-ordered radix sort (CPU drivers, see lane_digits.wgsl), pass 1 of 3: per-block histogram of the
// DIGIT_BITS-bit digit at SHIFT. hist is digit-major, hist[digit * groups + block], as in
// radix_count.wgsl, so that one exclusive scan yields every block's output offset for every digit.
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"
#include "sort/lane_digits.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;   // groups_x = sort blocks, count = keys
@group(0) @binding(1) var<storage, read> keys: array<u32>;
@group(0) @binding(2) var<storage, read_write> hist: array<u32>;
#if KEY_BASE
@group(0) @binding(3) var<storage, read> key_base: array<u32>;
#endif

var<workgroup> bins: array<u32, RADIX + 1u>;

@compute @workgroup_size(LANES)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(subgroup_invocation_id) lane: u32) {
    let block = lane_block(wg.x);
    let groups = lane_groups(info.groups_x);
    if block >= groups {
        return;
    }
    for (var d = lane; d <= RADIX; d += LANES) {
        bins[d] = 0u;
    }
    let base = key_offset();
    let keys_range = lane_keys(block, info.count);
    let start = keys_range.x;
    let end = keys_range.y;
    for (var i = start; i < end; i += LANES) {   // the same trip count in every lane
        let idx = i + lane;
        let d = select(NO_DIGIT, key_digit(keys[min(idx, end - 1u)], base), idx < end);
        let peers = digit_peers(d, lane);
        bins[d] += peers.x;   // every lane of digit d stores the same count
    }
    for (var d = lane; d < RADIX; d += LANES) {
        hist[d * groups + block] = bins[d];
    }
}
