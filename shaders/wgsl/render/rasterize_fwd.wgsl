// Forward rasterizer writing colour, alpha, normal and depth images to storage buffers, plus, with
// REPLAY (a define), the per-pixel final transmittance and contributor count that the backward pass
// replays from. Without it the compiler also drops the contributor count's tracking (render_only).
#include "render/rasterize_core.wgsl"

// Declared as vec4 arrays so that the tile walk can store a row of four pixels with one vec4 store per image
// (write_block_pixels below); write_pixel stores single components. The buffers are bound in multiples of
// 16 bytes (SurfelRasterizer.forward), so that every element of an image lies in some vec4.
@group(0) @binding(6) var<storage, read_write> out_color: array<vec4<f32>>;    // [H, W, CHANNELS]
@group(0) @binding(7) var<storage, read_write> out_alpha: array<vec4<f32>>;    // [H, W]
@group(0) @binding(8) var<storage, read_write> out_normal: array<vec4<f32>>;   // [H, W, 3]
@group(0) @binding(9) var<storage, read_write> out_depth: array<vec4<f32>>;    // [H, W]
#if REPLAY
@group(0) @binding(10) var<storage, read_write> out_final_t: array<vec4<f32>>; // [H, W]
@group(0) @binding(11) var<storage, read_write> out_last: array<vec4<u32>>;    // [H, W]
#endif

fn write_pixel(pix: vec2<u32>, r: PixelResult) {
    if pix.x >= params.image_size.x || pix.y >= params.image_size.y {
        return;
    }
    let p = pix.y * params.image_size.x + pix.x;
    for (var c = 0u; c < CHANNELS; c++) {
        let i = p * CHANNELS + c;
        out_color[i >> 2u][i & 3u] = r.color[c / 4u][c % 4u] + r.transmittance * background[c];
    }
    out_alpha[p >> 2u][p & 3u] = 1.0 - r.transmittance;
    out_normal[(3u * p) >> 2u][(3u * p) & 3u] = r.normal.x;
    out_normal[(3u * p + 1u) >> 2u][(3u * p + 1u) & 3u] = r.normal.y;
    out_normal[(3u * p + 2u) >> 2u][(3u * p + 2u) & 3u] = r.normal.z;
    out_depth[p >> 2u][p & 3u] = r.depth;
#if REPLAY
    out_final_t[p >> 2u][p & 3u] = r.transmittance;
    out_last[p >> 2u][p & 3u] = r.last;
#endif
}

#if TILE_WALK
// The tile walk's stores of one 4x8 block whose top left pixel is `block` (tile_walk_fwd.wgsl: lane l holds
// the pixels of column l & 3 in rows (l >> 2) + 2 k, k = 0-3, the first at `pix`, whose results are a-d;
// the tile walk serves at most 4 channels, so a.color[0] holds them all). Where the image's
// width is a multiple of 4, every row of the block starts at a multiple of 4 pixels, and lane j stores row j
// (gathered by shuffles) with one vec4 store per four values of each image, instead of each lane storing
// its four pixels' values one by one: lavapipe runs a store whose address differs between lanes as a loop
// over the lanes per component, so a vec4 costs about as much as one or two scalars. Images are
// bit-identical either way.
fn write_block_pixels(block: vec2<u32>, pix: vec2<u32>, sg_lane: u32, a: PixelResult, b: PixelResult,
                      c: PixelResult, d: PixelResult) {
    if params.image_size.x % 4u != 0u {   // uniform: pixel by pixel
        write_quad_pixels(pix, a, b, c, d);
        return;
    }
    if block.x >= params.image_size.x {
        return;
    }
    // Per value, the lane's four pixels (k = 0-3) as one vec4, then the row's four pixels' (row_values).
    let bg = background4();
    let col_a = a.color[0] + a.transmittance * bg;
    let col_b = b.color[0] + b.transmittance * bg;
    let col_c = c.color[0] + c.transmittance * bg;
    let col_d = d.color[0] + d.transmittance * bg;
    let r = row_values(vec4<f32>(col_a.x, col_b.x, col_c.x, col_d.x), sg_lane);   // channel 0
    let g = row_values(vec4<f32>(col_a.y, col_b.y, col_c.y, col_d.y), sg_lane);
    let bl = row_values(vec4<f32>(col_a.z, col_b.z, col_c.z, col_d.z), sg_lane);
    let w = row_values(vec4<f32>(col_a.w, col_b.w, col_c.w, col_d.w), sg_lane);
    let nx = row_values(vec4<f32>(a.normal.x, b.normal.x, c.normal.x, d.normal.x), sg_lane);
    let ny = row_values(vec4<f32>(a.normal.y, b.normal.y, c.normal.y, d.normal.y), sg_lane);
    let nz = row_values(vec4<f32>(a.normal.z, b.normal.z, c.normal.z, d.normal.z), sg_lane);
    let t = row_values(vec4<f32>(a.transmittance, b.transmittance, c.transmittance, d.transmittance), sg_lane);
    let depth = row_values(vec4<f32>(a.depth, b.depth, c.depth, d.depth), sg_lane);
#if REPLAY
    let last = row_values(bitcast<vec4<f32>>(vec4<u32>(a.last, b.last, c.last, d.last)), sg_lane);
#endif
    let y = block.y + sg_lane;
    if y < params.image_size.y {
        let q = (y * params.image_size.x + block.x) >> 2u;   // the row's first pixel / 4
        // The row's 4 x CHANNELS colour values, pixel-major, as CHANNELS vec4s (CHANNELS is a constant).
        if CHANNELS == 1u {
            out_color[q] = r;
        } else if CHANNELS == 2u {
            out_color[2u * q] = vec4<f32>(r.x, g.x, r.y, g.y);
            out_color[2u * q + 1u] = vec4<f32>(r.z, g.z, r.w, g.w);
        } else if CHANNELS == 3u {
            let rgb = interleave3(r, g, bl);
            out_color[3u * q] = rgb[0];
            out_color[3u * q + 1u] = rgb[1];
            out_color[3u * q + 2u] = rgb[2];
        } else {
            out_color[4u * q] = vec4<f32>(r.x, g.x, bl.x, w.x);
            out_color[4u * q + 1u] = vec4<f32>(r.y, g.y, bl.y, w.y);
            out_color[4u * q + 2u] = vec4<f32>(r.z, g.z, bl.z, w.z);
            out_color[4u * q + 3u] = vec4<f32>(r.w, g.w, bl.w, w.w);
        }
        out_alpha[q] = 1.0 - t;
        let n = interleave3(nx, ny, nz);
        out_normal[3u * q] = n[0];
        out_normal[3u * q + 1u] = n[1];
        out_normal[3u * q + 2u] = n[2];
        out_depth[q] = depth;
#if REPLAY
        out_final_t[q] = t;
        out_last[q] = bitcast<vec4<u32>>(last);
#endif
    }
}

// Four pixels' three values (x, y, z: one vec4 each, pixel i in component i) as the 12 floats of an
// [..., 3] image, in three vec4s.
fn interleave3(x: vec4<f32>, y: vec4<f32>, z: vec4<f32>) -> array<vec4<f32>, 3> {
    return array<vec4<f32>, 3>(vec4<f32>(x.x, y.x, z.x, x.y), vec4<f32>(y.y, z.y, x.z, y.z),
                               vec4<f32>(z.z, x.w, y.w, z.w));
}

// The four values in this lane's row of a 4x8 block (write_block_pixels) of a value whose four pixels k
// (rows (l >> 2) + 2 k of column l & 3) each lane l holds in `v`: row j's pixel x comes from lane
// 4 (j & 1) + x, its pixel j >> 1.
fn row_values(v: vec4<f32>, sg_lane: u32) -> vec4<f32> {
    let src = (sg_lane & 1u) << 2u;   // lane of column 0 of this lane's row
    let k = sg_lane >> 1u;
    return vec4<f32>(subgroupShuffle(v, src)[k], subgroupShuffle(v, src + 1u)[k],
                     subgroupShuffle(v, src + 2u)[k], subgroupShuffle(v, src + 3u)[k]);
}
#endif

#include "render/rasterize_entry.wgsl"
