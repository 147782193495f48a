// Copies the surfel renderer's rgba8 image onto the presentation target, pixel for pixel
// (fullscreen triangle, textureLoad at the fragment's pixel: no filtering, so the window shows exactly
// what an offscreen render of the same view holds).
// Define SRGB_TARGET: the target encodes linear->sRGB on write, so decode first to keep the bytes equal.

@group(0) @binding(0) var image: texture_2d<f32>;

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> @builtin(position) vec4<f32> {
    // Vertices (-1,-1), (3,-1), (-1,3) cover the viewport with one triangle.
    let p = vec2<f32>(f32((i << 1u) & 2u), f32(i & 2u));
    return vec4<f32>(p * 2.0 - 1.0, 0.0, 1.0);
}

fn srgb_to_linear(c: vec3<f32>) -> vec3<f32> {
    let lo = c / 12.92;
    let hi = pow((c + 0.055) / 1.055, vec3<f32>(2.4));
    return select(hi, lo, c <= vec3<f32>(0.04045));
}

@fragment
fn fs_main(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let c = textureLoad(image, vec2<i32>(pos.xy), 0);
    if SRGB_TARGET {
        return vec4<f32>(srgb_to_linear(c.rgb), 1.0);
    }
    return vec4<f32>(c.rgb, 1.0);
}
