// An RGBA image drawn as a quad at pixel corners over the frame (the stamp preview, the donor
// thumbnail). Two triangles from a vertex buffer of (pixel xy, image uv); alpha-blended, times a
// global opacity so the avatar stays visible under a stamp being placed.

struct ImageParams {
    size: vec4<f32>,   // xy: target size in pixels; z: opacity
};

@group(0) @binding(0) var<uniform> params: ImageParams;
@group(0) @binding(1) var image: texture_2d<f32>;
@group(0) @binding(2) var image_sampler: sampler;

struct VsOut {
    @builtin(position) pos: vec4<f32>,
    @location(0) uv: vec2<f32>,
};

@vertex
fn vs_main(@location(0) pixel: vec2<f32>, @location(1) uv: vec2<f32>) -> VsOut {
    var out: VsOut;
    out.pos = vec4<f32>(2.0 * pixel.x / params.size.x - 1.0, 1.0 - 2.0 * pixel.y / params.size.y, 0.0, 1.0);
    out.uv = uv;
    return out;
}

@fragment
fn fs_main(in: VsOut) -> @location(0) vec4<f32> {
    let c = textureSample(image, image_sampler, in.uv);
    return vec4<f32>(c.rgb, c.a * params.size.z);
}
