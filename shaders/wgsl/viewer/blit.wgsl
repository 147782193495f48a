// Copies the surfel renderer's rgba8 image onto the presentation target (fullscreen triangle).
// fs_main: pixel for pixel (textureLoad at the fragment's pixel: no filtering, so the window shows exactly
// what an offscreen render of the same view holds). fs_scaled: an image of another size (the viewer's
// cheaper interactive frames), stretched with bilinear filtering.
// Define SRGB_TARGET: the target encodes linear->sRGB on write, so decode first to keep the bytes equal.

@group(0) @binding(0) var image: texture_2d<f32>;
@group(0) @binding(1) var bilinear: sampler;   // fs_scaled only

struct VertexOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,   // 0..1 over the target, y down
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> VertexOut {
    // Vertices (-1,-1), (3,-1), (-1,3) cover the viewport with one triangle.
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return VertexOut(vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0), vec2<f32>(p.x, 1.0 - p.y));
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

fn present(c: vec4<f32>) -> vec4<f32> {
    if SRGB_TARGET {
        return vec4<f32>(srgb_to_linear(c.rgb), 1.0);
    }
    return vec4<f32>(c.rgb, 1.0);
}

@fragment
fn fs_main(v: VertexOut) -> @location(0) vec4<f32> {
    return present(textureLoad(image, vec2<i32>(v.pos.xy), 0));
}

@fragment
fn fs_scaled(v: VertexOut) -> @location(0) vec4<f32> {
    return present(textureSampleLevel(image, bilinear, v.uv, 0.0));
}
