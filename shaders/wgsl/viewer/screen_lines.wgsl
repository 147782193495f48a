// Screen-space polylines in pixel coordinates (the box / lasso outline while the user drags).

struct LineParams {
    size: vec4<f32>,   // xy: target size in pixels
    color: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: LineParams;

@vertex
fn vs_main(@location(0) pixel: vec2<f32>) -> @builtin(position) vec4<f32> {
    let ndc = vec2<f32>(2.0 * pixel.x / params.size.x - 1.0, 1.0 - 2.0 * pixel.y / params.size.y);
    return vec4<f32>(ndc, 0.0, 1.0);
}

@fragment
fn fs_main() -> @location(0) vec4<f32> {
    return params.color;
}
