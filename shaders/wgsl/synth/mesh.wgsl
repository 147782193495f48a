// Textured triangle mesh, rasterised by the fixed-function pipeline (synthetic ground truth only —
// the avatar itself is drawn by the surfel renderer). One vertex per triangle corner so that UV
// seams need no index juggling.
//
// Camera: OpenCV world->camera `w2c`, then `proj` maps camera space to clip space such that pixel
// (x, y) of the image has its centre at (x + 0.5, y + 0.5), like the surfel renderer's contract.

struct Uniforms {
    w2c: mat4x4<f32>,
    proj: mat4x4<f32>,
    light_dir: vec4<f32>,   // xyz: unit direction towards the light (world); w: shading strength in [0, 1]
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var albedo: texture_2d<f32>;
@group(0) @binding(2) var albedo_sampler: sampler;

struct VertexIn {
    @location(0) position: vec3<f32>,   // world space, metres
    @location(1) normal: vec3<f32>,     // world space, unnormalised
    @location(2) uv: vec2<f32>,         // u right, v up (OBJ convention)
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = u.proj * (u.w2c * vec4<f32>(v.position, 1.0));
    out.normal = v.normal;
    out.uv = vec2<f32>(v.uv.x, 1.0 - v.uv.y);  // texture row 0 is the top of the image
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    let base = textureSample(albedo, albedo_sampler, in.uv).rgb;
    // Two-sided Lambert plus ambient: inside surfaces (open sleeves, a hood) are lit like the outside.
    let n = normalize(in.normal + vec3<f32>(1e-12, 0.0, 0.0));
    let lambert = abs(dot(n, u.light_dir.xyz));
    let shade = mix(1.0, 0.55 + 0.45 * lambert, u.light_dir.w);
    // Alpha 1 marks coverage; the box filter on the host turns it into the soft mask.
    return vec4<f32>(clamp(base * shade, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}
