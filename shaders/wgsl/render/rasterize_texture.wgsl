// Forward rasterizer writing straight into an rgba8 storage texture (the viewer's path: no readback).
// Colour channels 0..2 are composited over the background; the texture's alpha is the coverage.
// The normal and depth sums that write_pixel ignores are dropped by the compiler already (a variant that
// skipped their shuffles and sums explicitly rendered the standard scene no faster on lavapipe).
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

#if TILE_WALK
// The tile walk's block (see rasterize_fwd.wgsl): each lane its four pixels.
fn write_block_pixels(block: vec2<u32>, pix: vec2<u32>, sg_lane: u32, a: PixelResult, b: PixelResult,
                      c: PixelResult, d: PixelResult) {
    write_quad_pixels(pix, a, b, c, d);
}
#endif

#include "render/rasterize_entry.wgsl"
