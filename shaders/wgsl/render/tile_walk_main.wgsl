// The tile walks' entry point (tile_walk_fwd.wgsl and tile_walk_bwd.wgsl define walk(tile, sg_lane)):
// one 8-lane subgroup per workgroup, walking one tile at a time. With WORK_QUEUE (lavapipe) one workgroup
// per driver thread takes the next tile, in row order, until none is left (rasterize_core.wgsl declares
// the queue); otherwise workgroup (x, y) walks tile (x, y).
@compute @workgroup_size(8)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(subgroup_invocation_id) sg_lane: u32) {
#if WORK_QUEUE
    let tiles = params.tile_grid.x * params.tile_grid.y;
    loop {
        let tile = take_work(1u, sg_lane);
        if tile >= tiles {
            break;
        }
        walk(tile, sg_lane);
    }
#else
    walk(wg.y * params.tile_grid.x + wg.x, sg_lane);
#endif
}
