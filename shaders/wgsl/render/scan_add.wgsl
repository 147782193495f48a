// Exclusive prefix sum, down pass: adds each block's scanned offset to its elements.
#include "common/scan_types.wgsl"


@group(0) @binding(0) var<uniform> scan: ScanParams;
@group(0) @binding(1) var<storage, read> block_offsets: array<u32>;
@group(0) @binding(2) var<storage, read_write> out: array<u32>;

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 256u;
    if i < scan.count {
        out[i] += block_offsets[i / SCAN_BLOCK];
    }
}
