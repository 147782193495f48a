// Face-ID render for editing: which face of the (morphed, posed) body mesh is visible at each pixel,
// and its camera depth. Drawn by the fixed-function pipeline with a depth buffer; vertices and faces
// are read from storage buffers so that one upload of the posed vertices serves every draw.
//
// Camera: OpenCV world->camera `w2c`, then `proj` maps camera space to clip space such that pixel
// (x, y) has its centre at (x + 0.5, y + 0.5), like the surfel renderer's contract.
// Output 0: face id + 1 (0 = background). Output 1: camera-space z of the visible point (metres).

struct Uniforms {
    w2c: mat4x4<f32>,
    proj: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> u: Uniforms;
@group(0) @binding(1) var<storage, read> vertices: array<f32>;   // [V * 3] world positions, metres
@group(0) @binding(2) var<storage, read> faces: array<u32>;      // [F * 3] vertex indices

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) id: u32,
    @location(1) z: f32,
};

@vertex
fn vs_main(@builtin(vertex_index) corner: u32) -> VertexOut {
    let v = faces[corner];
    let p = vec3<f32>(vertices[3u * v], vertices[3u * v + 1u], vertices[3u * v + 2u]);
    let pc = u.w2c * vec4<f32>(p, 1.0);
    var out: VertexOut;
    out.clip = u.proj * pc;
    out.id = corner / 3u + 1u;
    out.z = pc.z;
    return out;
}

struct FragmentOut {
    @location(0) id: u32,
    @location(1) z: f32,
};

@fragment
fn fs_main(in: VertexOut) -> FragmentOut {
    var out: FragmentOut;
    out.id = in.id;
    out.z = in.z;
    return out;
}
