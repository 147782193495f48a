// Lane-ordered radix sort (CPU drivers, see lane_digits.wgsl), pass 3 of 3: stable scatter of keys and
// values to their digit's place. A key's place: its digit's next free position in the block (the scanned
// histogram, advanced by the keys before it) plus the lanes before it in its step with the same digit.
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"
#include "sort/lane_digits.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;
@group(0) @binding(1) var<storage, read> hist: array<u32>;       // scanned: output offsets
@group(0) @binding(2) var<storage, read> keys_in: array<u32>;
@group(0) @binding(3) var<storage, read> vals_in: array<u32>;
@group(0) @binding(4) var<storage, read_write> keys_out: array<u32>;
@group(0) @binding(5) var<storage, read_write> vals_out: array<u32>;
#if KEY_BASE
@group(0) @binding(6) var<storage, read> key_base: array<u32>;
#endif

var<workgroup> next: array<u32, RADIX + 1u>;

@compute @workgroup_size(LANES)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(subgroup_invocation_id) lane: u32) {
    let block = lane_block(wg.x);
    let groups = lane_groups(info.groups_x);
    if block >= groups {
        return;
    }
    for (var d = lane; d < RADIX; d += LANES) {
        next[d] = hist[d * groups + block];
    }
    let base = key_offset();
    let keys_range = lane_keys(block, info.count);
    let start = keys_range.x;
    let end = keys_range.y;
    for (var i = start; i < end; i += LANES) {   // the same trip count in every lane
        let idx = min(i + lane, end - 1u);
        let key = keys_in[idx];
        let d = select(NO_DIGIT, key_digit(key, base), i + lane < end);
        let peers = digit_peers(d, lane);
        let first = next[d];
        next[d] = first + peers.x;
        if i + lane < end {
            keys_out[first + peers.y] = key;
            vals_out[first + peers.y] = vals_in[idx];
        }
    }
}
