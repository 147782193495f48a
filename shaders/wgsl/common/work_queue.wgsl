// Work handed out at run time, for passes dispatched with one workgroup per CPU-driver thread (WORK_QUEUE;
// gma/render/rasterizer.py, RasterOptions.work_queues: lavapipe only).
//
// Lavapipe does not hand a dispatch's workgroups to its threads one at a time: each of its N threads takes
// one contiguous run of W / N of them (llvmpipe's compute thread pool, iter_per_thread), so a pass lasts as
// long as its slowest thread's share. Shares differ in cost (a body's upper half holds more surfels than
// its legs), and a thread can lose its core for a while: to other processes, or right after a caller's
// torch op to torch's OpenMP workers, which spin before they sleep.
// With a queue each subgroup takes the next piece of work from a counter in `work_queue` (declared by the
// including shader at a binding of its own, cleared before the pass) until none is left, so a slowed
// thread takes fewer pieces instead of holding the pass up. The results do not depend on which thread
// took what: every piece writes only its own outputs.

// The first of `amount` consecutive work items for this subgroup (the same in every lane); at or past the
// total once all are taken. Lane 0 takes them; a CPU driver runs a subgroup as one SIMD thread.
fn take_work(amount: u32, sg_lane: u32) -> u32 {
    var first = 0u;
    if sg_lane == 0u {
        first = atomicAdd(&work_queue[0], amount);
    }
    return subgroupBroadcast(first, 0u);
}

// Surfels per piece in the per-surfel passes: 8 steps of an 8-lane subgroup, so that the counter is
// touched once per 64 surfels.
const QUEUE_CHUNK: u32 = 64u;
