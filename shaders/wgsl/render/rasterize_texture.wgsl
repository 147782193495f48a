// Forward rasterizer writing straight into an rgba8 storage texture (the viewer's path: no readback).
// Colour channels 0..2 are composited over the background; the texture's alpha is the coverage.
#include "render/rasterize_core.wgsl"

@group(0) @binding(6) var out_texture: texture_storage_2d<rgba8unorm, write>;

fn write_pixel(pix: vec2<u32>, r: PixelResult) {
    if pix.x >= params.image_size.x || pix.y >= params.image_size.y {
        return;
    }
    let T = r.transmittance;
    let rgb = r.color[0].xyz + T * vec3<f32>(background[0], background[1], background[2]);
    textureStore(out_texture, vec2<i32>(pix), vec4<f32>(clamp(rgb, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0 - T));
}

// One-dimensional workgroups: subgroup builtins are only defined for those.
#if USE_SUBGROUPS
@compute @workgroup_size(64)   // RASTER_THREADS: four pixels per thread (see composite_quad)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) sg_lane: u32, @builtin(subgroup_id) sg_id: u32) {
    let pix = wg.xy * TILE_SIZE + tile_pixel_quad(lid);
    var a: PixelBlend;
    var b: PixelBlend;
    var c: PixelBlend;
    var d: PixelBlend;
    composite_quad(wg.y * params.tile_grid.x + wg.x, pix, lid, sg_lane, sg_id, &a, &b, &c, &d);
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
