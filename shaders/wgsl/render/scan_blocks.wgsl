// Exclusive prefix sum, level pass: each workgroup scans SCAN_BLOCK values and writes its block total.
// With GATHER (a define) the values are read as values[index[i]], which scans the tile counts in depth
// order without materialising them.
#include "common/scan_types.wgsl"
#include "common/math.wgsl"

// 64 threads of 16 values: one thread scans the 64 partial sums alone (cheaper than a log-step scan's
// barriers on CPUs). With 256 threads of 4 values that serial pass would be 4x longer.
const SCAN_WG: u32 = 64u;
const SCAN_ITEMS: u32 = 16u;


@group(0) @binding(0) var<uniform> scan: ScanParams;
@group(0) @binding(1) var<storage, read> values: array<u32>;
@group(0) @binding(2) var<storage, read> index: array<u32>;
@group(0) @binding(3) var<storage, read_write> out: array<u32>;
@group(0) @binding(4) var<storage, read_write> block_sums: array<u32>;

var<workgroup> partial: array<u32, SCAN_WG>;

fn load(i: u32) -> u32 {
    if i >= scan.count {
        return 0u;
    }
    if GATHER {
        return values[index[i]];
    }
    return values[i];
}

@compute @workgroup_size(SCAN_WG)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let start = wg.x * SCAN_BLOCK + lid * SCAN_ITEMS;
    var v: array<u32, SCAN_ITEMS>;
    var sum = 0u;
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        v[k] = load(start + k);
        sum += v[k];
    }
    partial[lid] = sum;
    workgroupBarrier();
    if lid == 0u {
        var run = 0u;
        for (var t = 0u; t < SCAN_WG; t++) {
            let s = partial[t];
            partial[t] = run;
            run += s;
        }
        block_sums[wg.x] = run;
    }
    workgroupBarrier();
    var run = partial[lid];
    for (var k = 0u; k < SCAN_ITEMS; k++) {
        if start + k < scan.count {
            out[start + k] = run;
        }
        run += v[k];
    }
}
