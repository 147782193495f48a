// Forward rasterizer writing colour, alpha, normal and depth images to storage buffers, plus, with
// REPLAY (a define), the per-pixel final transmittance and contributor count that the backward pass
// replays from. Without it the compiler also drops the contributor count's tracking (render_only).
#include "render/rasterize_core.wgsl"

@group(0) @binding(6) var<storage, read_write> out_color: array<f32>;    // [H, W, CHANNELS]
@group(0) @binding(7) var<storage, read_write> out_alpha: array<f32>;    // [H, W]
@group(0) @binding(8) var<storage, read_write> out_normal: array<f32>;   // [H, W, 3]
@group(0) @binding(9) var<storage, read_write> out_depth: array<f32>;    // [H, W]
#if REPLAY
@group(0) @binding(10) var<storage, read_write> out_final_t: array<f32>; // [H, W]
@group(0) @binding(11) var<storage, read_write> out_last: array<u32>;    // [H, W]
#endif

fn write_pixel(pix: vec2<u32>, r: PixelResult) {
    if pix.x >= params.image_size.x || pix.y >= params.image_size.y {
        return;
    }
    let p = pix.y * params.image_size.x + pix.x;
    for (var c = 0u; c < CHANNELS; c++) {
        out_color[p * CHANNELS + c] = r.color[c / 4u][c % 4u] + r.transmittance * background[c];
    }
    out_alpha[p] = 1.0 - r.transmittance;
    out_normal[3u * p] = r.normal.x;
    out_normal[3u * p + 1u] = r.normal.y;
    out_normal[3u * p + 2u] = r.normal.z;
    out_depth[p] = r.depth;
#if REPLAY
    out_final_t[p] = r.transmittance;
    out_last[p] = r.last;
#endif
}

#include "render/rasterize_entry.wgsl"
