// Surfel placement on the posed mesh, one invocation per surfel:
//   mean  = u·V1 + v·V2 + (1-u-v)·V3 + d·N_f
//   quat  = q_face ⊗ q_local,  face frame columns (t = V1→V2, n × t, n)
//   scale = s_local · sqrt(area)
// written straight into the renderer's packed input buffers. Reference: gma.body.placement.place_surfels.
#include "common/body_types.wgsl"

@group(0) @binding(0) var<uniform> params: BodyParams;
@group(0) @binding(1) var<storage, read> posed: array<f32>;             // [V*3]
@group(0) @binding(2) var<storage, read> faces: array<u32>;             // [F*3]
@group(0) @binding(3) var<storage, read> surfels: array<SurfelLocal>;   // [N]
@group(0) @binding(4) var<storage, read_write> means: array<f32>;       // [N*3]
@group(0) @binding(5) var<storage, read_write> quats: array<f32>;       // [N*4] (w, x, y, z)
@group(0) @binding(6) var<storage, read_write> scales: array<f32>;      // [N*2]

fn vertex(i: u32) -> vec3<f32> {
    return vec3<f32>(posed[3u * i], posed[3u * i + 1u], posed[3u * i + 2u]);
}

// Shepperd's method with the same pivot choice as gma.body.placement.rotmat_to_quat (first maximum of
// trace, m00, m11, m22), so both paths return the same sign. Columns c0, c1, c2; m[r][c] = c_c[r].
fn rotmat_to_quat(c0: vec3<f32>, c1: vec3<f32>, c2: vec3<f32>) -> vec4<f32> {
    let m00 = c0.x; let m11 = c1.y; let m22 = c2.z;
    let m01 = c1.x; let m02 = c2.x; let m10 = c0.y; let m12 = c2.y; let m20 = c0.z; let m21 = c1.z;
    let tr = m00 + m11 + m22;
    var pivot = 0u;
    var best = tr;
    if (m00 > best) { pivot = 1u; best = m00; }
    if (m11 > best) { pivot = 2u; best = m11; }
    if (m22 > best) { pivot = 3u; best = m22; }
    if (pivot == 0u) {
        let s = sqrt(max(1.0 + tr, BODY_EPS)) * 2.0;
        return vec4<f32>(0.25 * s, (m21 - m12) / s, (m02 - m20) / s, (m10 - m01) / s);
    }
    if (pivot == 1u) {
        let s = sqrt(max(1.0 + m00 - m11 - m22, BODY_EPS)) * 2.0;
        return vec4<f32>((m21 - m12) / s, 0.25 * s, (m01 + m10) / s, (m02 + m20) / s);
    }
    if (pivot == 2u) {
        let s = sqrt(max(1.0 + m11 - m00 - m22, BODY_EPS)) * 2.0;
        return vec4<f32>((m02 - m20) / s, (m01 + m10) / s, 0.25 * s, (m12 + m21) / s);
    }
    let s = sqrt(max(1.0 + m22 - m00 - m11, BODY_EPS)) * 2.0;
    return vec4<f32>((m10 - m01) / s, (m02 + m20) / s, (m12 + m21) / s, 0.25 * s);
}

// Hamilton product a ⊗ b, (w, x, y, z).
fn quat_mul(a: vec4<f32>, b: vec4<f32>) -> vec4<f32> {
    return vec4<f32>(
        a.x * b.x - a.y * b.y - a.z * b.z - a.w * b.w,
        a.x * b.y + a.y * b.x + a.z * b.w - a.w * b.z,
        a.x * b.z - a.y * b.w + a.z * b.x + a.w * b.y,
        a.x * b.w + a.y * b.z - a.z * b.y + a.w * b.x,
    );
}

@compute @workgroup_size(WG)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = body_item_index(gid, nwg, WG);
    if (i >= params.count) {
        return;
    }
    let s = surfels[i];
    let a = vertex(faces[3u * s.face]);
    let b = vertex(faces[3u * s.face + 1u]);
    let c = vertex(faces[3u * s.face + 2u]);
    let cr = cross(b - a, c - a);
    let n = body_safe_normalize(cr);
    let mean = s.u * a + s.v * b + (1.0 - s.u - s.v) * c + s.d * n;
    let t = body_safe_normalize(b - a);
    let bt = cross(n, t);
    let q = quat_mul(rotmat_to_quat(t, bt, n), s.quat);
    let size = sqrt(max(0.5 * length(cr), 0.0) + BODY_EPS);
    means[3u * i] = mean.x;
    means[3u * i + 1u] = mean.y;
    means[3u * i + 2u] = mean.z;
    quats[4u * i] = q.x;
    quats[4u * i + 1u] = q.y;
    quats[4u * i + 2u] = q.z;
    quats[4u * i + 3u] = q.w;
    scales[2u * i] = s.scale.x * size;
    scales[2u * i + 1u] = s.scale.y * size;
}
