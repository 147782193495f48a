// The forward rasterizers' entry point, shared by the buffer and texture variants: each defines
// write_pixel(pix, result) and includes this file (WGSL resolves module-scope names in any order).

// One-dimensional workgroups: subgroup builtins are only defined for those.
#if TILE_WALK
#include "render/tile_walk_fwd.wgsl"
#else
#if USE_SUBGROUPS
@compute @workgroup_size(64)   // RASTER_THREADS: four pixels per thread (see composite_quad)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) sg_lane: u32, @builtin(subgroup_id) sg_id: u32) {
    let pix = wg.xy * TILE_SIZE + tile_pixel_quad(lid);
    var a: PixelBlend;
    var b: PixelBlend;
    var c: PixelBlend;
    var d: PixelBlend;
    composite_quad(wg.y * params.tile_grid.x + wg.x, pix, sg_lane, sg_id, &a, &b, &c, &d);
    write_pixel(pix, a.result);
    write_pixel(pix + ROW_STEP, b.result);
    write_pixel(pix + 2u * ROW_STEP, c.result);
    write_pixel(pix + 3u * ROW_STEP, d.result);
}
#else
@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let pix = wg.xy * TILE_SIZE + tile_pixel(lid);
    let inside = pix.x < params.image_size.x && pix.y < params.image_size.y;
    write_pixel(pix, composite_pixel(wg.y * params.tile_grid.x + wg.x, vec2<f32>(pix) + 0.5, inside, lid));
}
#endif
#endif
