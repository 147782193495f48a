// Structs and helpers shared by the body passes (shaders/wgsl/body/*). Python mirrors of the structs:
// gma/body/placement.py (SURFEL_LOCAL_DTYPE) and gma/body/gpu_posing.py (the params packing).

// One surfel bound to the mesh: face id, barycentric (u, v) of corners 1 and 2, normal offset d (m),
// in-face rotation quaternion (w, x, y, z) and in-face scale (multiplied by sqrt(face area)).
struct SurfelLocal {
    face: u32,
    u: f32,
    v: f32,
    d: f32,
    quat: vec4<f32>,
    scale: vec2<f32>,
    _pad: vec2<f32>,
};

// Per-dispatch counts. `count` is the number of items (vertices or surfels); `k` the influences per
// vertex; `n_bones` bounds bone indices.
struct BodyParams {
    count: u32,
    k: u32,
    n_bones: u32,
    _pad: u32,
};

// Same rule as gma.body.geometry.safe_normalize: divide by max(|x|, 1e-12), zero stays zero.
const BODY_EPS: f32 = 1e-12;

fn body_safe_normalize(x: vec3<f32>) -> vec3<f32> {
    return x / max(length(x), BODY_EPS);
}

// Flat item index of a 2D dispatch (dispatches over 65535 workgroups wrap into y).
fn body_item_index(gid: vec3<u32>, nwg: vec3<u32>, wg: u32) -> u32 {
    return gid.x + gid.y * nwg.x * wg;
}

