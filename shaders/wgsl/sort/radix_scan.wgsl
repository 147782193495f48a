// Radix sort, pass 2 of 3: exclusive scan of the digit-major histogram in place (one workgroup). Define:
// DIGITS, the digits per block (16 for radix_count.wgsl's, 2^DIGIT_BITS for lane_count.wgsl's).
#include "common/render_types.wgsl"
#include "common/sort_types.wgsl"

@group(0) @binding(0) var<storage, read> info: DispatchInfo;
@group(0) @binding(1) var<storage, read_write> hist: array<u32>;

const SCAN_WG: u32 = 256u;
var<workgroup> partial: array<u32, SCAN_WG>;

@compute @workgroup_size(SCAN_WG)
fn main(@builtin(local_invocation_index) lid: u32) {
    let total = DIGITS * ((info.groups_x + GROUP_BLOCKS - 1u) / GROUP_BLOCKS);
    let chunk = (total + SCAN_WG - 1u) / SCAN_WG;
    let begin = min(lid * chunk, total);
    let end = min(begin + chunk, total);
    var sum = 0u;
    for (var i = begin; i < end; i++) {
        sum += hist[i];
    }
    partial[lid] = sum;
    workgroupBarrier();
    // 256 partial sums: one thread scans them, cheaper than a log-step scan's barriers on CPUs.
    if lid == 0u {
        var run = 0u;
        for (var t = 0u; t < SCAN_WG; t++) {
            let v = partial[t];
            partial[t] = run;
            run += v;
        }
    }
    workgroupBarrier();
    var run = partial[lid];
    for (var i = begin; i < end; i++) {
        let v = hist[i];
        hist[i] = run;
        run += v;
    }
}
