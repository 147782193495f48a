// The forward rasterizers' entry point, shared by the buffer and texture variants: each defines
// write_pixel(pix, result), with TILE_WALK also write_block_pixels (a 4x8 block's results), and includes
// this file (WGSL resolves module-scope names in any order).

#if USE_SUBGROUPS
// A thread's four pixels (first pixel `pix`, then ROW_STEPs down: tile_pixel_quad), one by one.
fn write_quad_pixels(pix: vec2<u32>, a: PixelResult, b: PixelResult, c: PixelResult, d: PixelResult) {
    write_pixel(pix, a);
    write_pixel(pix + ROW_STEP, b);
    write_pixel(pix + 2u * ROW_STEP, c);
    write_pixel(pix + 3u * ROW_STEP, d);
}
#endif

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
    write_quad_pixels(pix, a.result, b.result, c.result, d.result);
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
