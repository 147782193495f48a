// Linear-blend skinning: posed[v] = Σ_k w[v,k] · T[i[v,k]] · (rest[v], 1), one invocation per vertex.
// Reference: gma.body.skinning.linear_blend_skinning.
#include "common/body_types.wgsl"

@group(0) @binding(0) var<uniform> params: BodyParams;
@group(0) @binding(1) var<storage, read> rest: array<f32>;          // [V*3] canonical (morphed) vertices
@group(0) @binding(2) var<storage, read> skin_indices: array<u32>;  // [V*K]
@group(0) @binding(3) var<storage, read> skin_weights: array<f32>;  // [V*K]
@group(0) @binding(4) var<storage, read> bones: array<vec4<f32>>;   // [J*3] rows of each 3x4 transform
@group(0) @binding(5) var<storage, read_write> posed: array<f32>;   // [V*3]

@compute @workgroup_size(WG)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let v = body_item_index(gid, nwg, WG);
    if (v >= params.count) {
        return;
    }
    let p = vec4<f32>(rest[3u * v], rest[3u * v + 1u], rest[3u * v + 2u], 1.0);
    var acc = vec3<f32>(0.0);
    for (var k = 0u; k < params.k; k = k + 1u) {
        let w = skin_weights[v * params.k + k];
        if (w == 0.0) {
            continue;  // padding slots; also skips their (possibly meaningless) bone index
        }
        let j = min(skin_indices[v * params.k + k], params.n_bones - 1u);
        acc = acc + w * vec3<f32>(dot(bones[3u * j], p), dot(bones[3u * j + 1u], p), dot(bones[3u * j + 2u], p));
    }
    posed[3u * v] = acc.x;
    posed[3u * v + 1u] = acc.y;
    posed[3u * v + 2u] = acc.z;
}
