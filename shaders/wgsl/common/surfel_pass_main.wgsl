// The entry point of a per-surfel pass (emit_isects.wgsl, project_bwd.wgsl): the includer defines
// surfel_work(i), which does nothing for i at or past params.num_surfels. One thread per surfel, or with
// WORK_QUEUE (lavapipe; the includer declares `work_queue` at a binding of its own) one workgroup per
// driver thread, whose subgroups take chunks of QUEUE_CHUNK surfels until none is left
// (common/work_queue.wgsl).
#if WORK_QUEUE
#include "common/work_queue.wgsl"

@compute @workgroup_size(256)
fn main(@builtin(subgroup_invocation_id) sg_lane: u32, @builtin(subgroup_size) sg_size: u32) {
    loop {
        let first = take_work(QUEUE_CHUNK, sg_lane);
        if first >= params.num_surfels {
            break;
        }
        for (var j = 0u; j < QUEUE_CHUNK; j += sg_size) {
            surfel_work(first + j + sg_lane);
        }
    }
}
#else
@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    surfel_work(gid.x);
}
#endif
