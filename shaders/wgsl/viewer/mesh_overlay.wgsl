// Overlays drawn from the posed body mesh that lives in GPU buffers (written by body/skin.wgsl):
// a depth pre-pass of the mesh, the wireframe, face normals, coarse surfels (one disc per face) and
// the selection highlight. Vertex shaders fetch positions by index from storage buffers, so nothing
// is copied per frame. Positions are packed f32 triples (no vec3 padding), faces packed u32 triples.

struct OverlayParams {
    mvp: mat4x4<f32>,       // world -> clip (OpenCV camera folded into a WebGPU projection)
    color: vec4<f32>,       // rgba of the overlay being drawn
    settings: vec4<f32>,    // x: normal length (m), y: coarse disc radius factor, z: depth offset (clip w fraction)
};

@group(0) @binding(0) var<uniform> params: OverlayParams;
@group(0) @binding(1) var<storage, read> positions: array<f32>;
@group(0) @binding(2) var<storage, read> faces: array<u32>;
@group(0) @binding(3) var<storage, read> items: array<u32>;  // edges (pairs) or selected face ids

struct VsOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) color: vec4<f32>,
    @location(1) local: vec2<f32>,
};

fn vertex_pos(v: u32) -> vec3<f32> {
    return vec3<f32>(positions[3u * v], positions[3u * v + 1u], positions[3u * v + 2u]);
}

fn corner(f: u32, k: u32) -> vec3<f32> {
    return vertex_pos(faces[3u * f + k]);
}

fn to_clip(p: vec3<f32>) -> vec4<f32> {
    return params.mvp * vec4<f32>(p, 1.0);
}

fn out_of(clip: vec4<f32>, color: vec4<f32>) -> VsOut {
    var o: VsOut;
    o.clip = clip;
    o.color = color;
    o.local = vec2<f32>(0.0);
    return o;
}

// Depth pre-pass: every face, pushed back slightly so lines and highlights on the surface win the
// depth test (WebGPU forbids depth bias on line topologies, so the bias goes here instead).
@vertex
fn vs_depth(@builtin(vertex_index) i: u32) -> VsOut {
    var c = to_clip(corner(i / 3u, i % 3u));
    c.z = c.z + params.settings.z * c.w;
    return out_of(c, vec4<f32>(0.0));
}

@vertex
fn vs_wire(@builtin(vertex_index) i: u32) -> VsOut {
    return out_of(to_clip(vertex_pos(items[i])), params.color);
}

@vertex
fn vs_highlight(@builtin(vertex_index) i: u32) -> VsOut {
    return out_of(to_clip(corner(items[i / 3u], i % 3u)), params.color);
}

fn face_frame(f: u32) -> mat3x3<f32> {
    let a = corner(f, 0u);
    let b = corner(f, 1u);
    let c = corner(f, 2u);
    let n = cross(b - a, c - a);  // length = 2 * area
    return mat3x3<f32>((a + b + c) / 3.0, n, b - a);
}

@vertex
fn vs_normals(@builtin(vertex_index) i: u32) -> VsOut {
    let fr = face_frame(i / 2u);
    let n = normalize(fr[1] + vec3<f32>(0.0, 0.0, 1e-20));
    let p = fr[0] + f32(i % 2u) * params.settings.x * n;
    return out_of(to_clip(p), params.color);
}

// Coarse surfels: one disc per face in the face plane, radius ~ sqrt(area) (the coarse layer's scale).
@vertex
fn vs_coarse(@builtin(vertex_index) i: u32) -> VsOut {
    let fr = face_frame(i / 6u);
    let area2 = length(fr[1]);
    let n = fr[1] / max(area2, 1e-20);
    let t = normalize(fr[2] + vec3<f32>(1e-20, 0.0, 0.0));
    let s = cross(n, t);
    // Two triangles of a quad; corners in [-1, 1]^2.
    var quad = array<vec2<f32>, 6>(vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, -1.0), vec2<f32>(1.0, 1.0),
                                   vec2<f32>(-1.0, -1.0), vec2<f32>(1.0, 1.0), vec2<f32>(-1.0, 1.0));
    let q = quad[i % 6u];
    let r = params.settings.y * sqrt(0.5 * area2);
    var o = out_of(to_clip(fr[0] + r * (q.x * t + q.y * s)), vec4<f32>(0.5 + 0.5 * n, 1.0));
    o.local = q;
    return o;
}

@fragment
fn fs_color(v: VsOut) -> @location(0) vec4<f32> {
    return v.color;
}

@fragment
fn fs_disc(v: VsOut) -> @location(0) vec4<f32> {
    if dot(v.local, v.local) > 1.0 {
        discard;
    }
    return v.color;
}
