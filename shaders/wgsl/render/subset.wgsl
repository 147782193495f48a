// A thinner copy of a surfel set for the viewer's interactive frames: the surfels order[0 .. count), each
// covering `stride` times its area so that the body stays closed (see widen()). One thread per kept
// surfel. Define: CHANNELS.

struct SubsetParams {
    count: u32,          // kept surfels: ceil(source count / stride)
    stride: u32,
    scale_boost: f32,    // sqrt(stride)
    _pad: u32,
};

@group(0) @binding(0) var<uniform> params: SubsetParams;
@group(0) @binding(1) var<storage, read> means: array<f32>;       // [N, 3]
@group(0) @binding(2) var<storage, read> quats: array<f32>;       // [N, 4]
@group(0) @binding(3) var<storage, read> scales: array<f32>;      // [N, 2]
@group(0) @binding(4) var<storage, read> opacities: array<f32>;   // [N]
@group(0) @binding(5) var<storage, read> colors: array<f32>;      // [N, CHANNELS]
@group(0) @binding(6) var<storage, read_write> out_means: array<f32>;
@group(0) @binding(7) var<storage, read_write> out_quats: array<f32>;
@group(0) @binding(8) var<storage, read_write> out_scales: array<f32>;
@group(0) @binding(9) var<storage, read_write> out_opacities: array<f32>;
@group(0) @binding(10) var<storage, read_write> out_colors: array<f32>;
@group(0) @binding(11) var<storage, read> order: array<u32>;       // surfel ids, best spread first

// Scales covering `stride` times the area: the short axis grows first (up to the long one), then both
// alike. Growing both axes by sqrt(stride) would also lengthen long thin surfels into streaks.
fn widen(s: vec2<f32>) -> vec2<f32> {
    let stride = f32(params.stride);
    let short = min(s.x, s.y);
    let long = max(s.x, s.y);
    if short * stride <= long {
        return select(vec2<f32>(s.x, s.y * stride), vec2<f32>(s.x * stride, s.y), s.x < s.y);
    }
    return vec2<f32>(sqrt(short * long) * params.scale_boost);
}

@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>) {
    let j = gid.x;
    if j >= params.count {
        return;
    }
    let i = order[j];
    for (var c = 0u; c < 3u; c++) {
        out_means[3u * j + c] = means[3u * i + c];
    }
    for (var c = 0u; c < 4u; c++) {
        out_quats[4u * j + c] = quats[4u * i + c];
    }
    let wide = widen(vec2<f32>(scales[2u * i], scales[2u * i + 1u]));
    out_scales[2u * j] = wide.x;
    out_scales[2u * j + 1u] = wide.y;
    out_opacities[j] = opacities[i];
    for (var c = 0u; c < CHANNELS; c++) {
        out_colors[CHANNELS * j + c] = colors[CHANNELS * i + c];
    }
}
