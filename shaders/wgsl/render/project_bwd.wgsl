// Projection backward: one thread per surfel. Chains the rasterizer's gradients with respect to the ray
// plane (ProjectedSurfel: the ray transform T in the form the rasterizers evaluate, ray_plane.wgsl), the
// reference point (the projected centre), the camera-space normal and the depth down to means, quaternions
// and scales, by recomputing the forward projection (cheaper than storing its intermediates).
// Define COLOR_IN_PROJ (with CHANNELS <= 4): the rasterizer left no normal or depth gradients and put
// the colour gradients in their slots (12..); they are copied out to v_colors here (rasterize_bwd.wgsl).
// Define GRAD_RECORDS: the rasterizer wrote one gradient record per intersection that a pixel took
// (store_record in tile_walk_bwd.wgsl), at its tile-sorted place; a surfel's record slots (that place
// + 1, or 0: no record) lie at [record_base, record_base + tile count), and its records are summed here
// in that order, the same on every run, into the projection and colour gradients (NORMAL_DEPTH_GRADS
// says which record layout).
// COLORS_OUT: this pass writes v_colors (with COLOR_IN_PROJ or GRAD_RECORDS).
#include "common/render_types.wgsl"
#include "common/math.wgsl"
#include "render/ray_plane.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> means: array<f32>;        // [N, 3]
@group(0) @binding(2) var<storage, read> quats: array<f32>;        // [N, 4]
@group(0) @binding(3) var<storage, read> scales: array<f32>;       // [N, 2]
@group(0) @binding(4) var<storage, read> tile_counts: array<u32>;  // [N], 0 when culled
#if GRAD_RECORDS
#if RECORD_TEXELS
// The records as the backward's tile walk wrote them into a texture (texel_at; see
// gma/render/surfel_texels.py): on lavapipe a texel fetch gathers for all lanes at once.
@group(0) @binding(13) var record_texels: texture_storage_2d<rgba32float, read>;
fn load_record(t: u32) -> vec4<f32> {
    return textureLoad(record_texels, texel_at(t));
}
#else
@group(0) @binding(5) var<storage, read> records: array<vec4<f32>>;  // [isects, RECORD_VEC4S]
fn load_record(t: u32) -> vec4<f32> {
    return records[t];
}
#endif
@group(0) @binding(11) var<storage, read> record_base: array<u32>;   // [N] by surfel id
@group(0) @binding(12) var<storage, read> record_slots: array<u32>;  // [isects] by emission index (see above)
#else
@group(0) @binding(5) var<storage, read> v_proj: array<f32>;       // [N, 16] (layout: grad_atomics.wgsl)
#endif
@group(0) @binding(6) var<storage, read_write> v_means: array<f32>;     // [N, 3]
@group(0) @binding(7) var<storage, read_write> v_quats: array<f32>;     // [N, 4]
@group(0) @binding(8) var<storage, read_write> v_scales: array<f32>;    // [N, 2]
@group(0) @binding(9) var<storage, read_write> v_opacities: array<f32>; // [N]
#if COLORS_OUT
@group(0) @binding(10) var<storage, read_write> v_colors: array<f32>;   // [N, CHANNELS]
#endif

// The rasterizer's gradients of one surfel (see G_* in grad_atomics.wgsl).
struct RasterGrads {
    v_plane: RayPlane,   // d loss / d(p_ref, dp_dx, dp_dy)
    v_mu2d: vec2<f32>,   // d loss / d reference point
    v_opacity: f32,
    v_normal: vec3<f32>,
    v_depth: f32,
    v_color: vec4<f32>,   // channels 0-3, where this pass writes them (COLORS_OUT)
}

#if GRAD_RECORDS
#if NORMAL_DEPTH_GRADS
const RECORD_VEC4S: u32 = 5u;
#else
const RECORD_VEC4S: u32 = 4u;
#endif

// Slot e of a surfel's record slots, which end before `end`; 0 (no record) past them.
fn slot_before(e: u32, end: u32) -> u32 {
    return select(0u, record_slots[min(e, end - 1u)], e < end);
}

// Vec4 k of the record in `slot` (its tile-sorted place + 1; for slot 0, which has none, record 0's:
// every lane fetches, and the sum selects zero instead, so that whatever a stale record holds, NaN
// included, stays out of it, and no divergent branch is needed).
fn record_vec4(slot: u32, k: u32) -> vec4<f32> {
    return load_record((max(slot, 1u) - 1u) * RECORD_VEC4S + k);
}

// `v` where its record exists (slot != 0), else zero.
fn if_written(v: vec4<f32>, slot: u32) -> vec4<f32> {
    return select(vec4<f32>(0.0), v, slot != 0u);
}

// Sum of surfel i's records. A record holds V0-15 of store_record pairwise, (V[l], V[l + 8]) as vec2
// number l, so its vec4s are (V0 V8 V1 V9) (V2 V10 V3 V11) (V4 V12 V5 V13) (V6 V14 V7 V15), with
// V0-2 = dL/dp_ref, V3 opacity, V4-6 = dL/ddp_dx, V7 c.x, V8-10 = dL/ddp_dy, V11 c.y, V12-15 = normal and
// depth (a fifth vec4 then holds the colours) or the colours. Tried: one thread per intersection in
// tile order summing its surfel's records where it holds the first (neighbouring threads gather
// neighbouring tiles' records): slower, as most lanes idle.
// Four slots per step, in slot order as before (so the sums are bit-identical): all sixteen fetches of
// a step (cache misses mostly: the tile walk wrote the records in tile order, they are read here by
// surfel) are issued before any is added, and most subgroups are done after one step (a surfel has two
// or three slots on the standard scene), where one slot per step runs as many steps as the largest count
// of the subgroup's eight surfels. Written differently it loses the gain: a record struct per slot,
// fetched and selected slot by slot, or each slot's index loaded twice, once under a short-circuit `&&`.
fn raster_grads(i: u32) -> RasterGrads {
    let first = record_base[i];
    let end = min(first + tile_counts[i], params.isect_capacity);
    var s0 = vec4<f32>(0.0);
    var s1 = vec4<f32>(0.0);
    var s2 = vec4<f32>(0.0);
    var s3 = vec4<f32>(0.0);
    var s4 = vec4<f32>(0.0);
    for (var e = first; e < end; e += 4u) {
        let sa = record_slots[e];
        let sb = slot_before(e + 1u, end);
        let sc = slot_before(e + 2u, end);
        let sd = slot_before(e + 3u, end);
        let a0 = record_vec4(sa, 0u);
        let b0 = record_vec4(sb, 0u);
        let c0 = record_vec4(sc, 0u);
        let d0 = record_vec4(sd, 0u);
        let a1 = record_vec4(sa, 1u);
        let b1 = record_vec4(sb, 1u);
        let c1 = record_vec4(sc, 1u);
        let d1 = record_vec4(sd, 1u);
        let a2 = record_vec4(sa, 2u);
        let b2 = record_vec4(sb, 2u);
        let c2 = record_vec4(sc, 2u);
        let d2 = record_vec4(sd, 2u);
        let a3 = record_vec4(sa, 3u);
        let b3 = record_vec4(sb, 3u);
        let c3 = record_vec4(sc, 3u);
        let d3 = record_vec4(sd, 3u);
        s0 += if_written(a0, sa);
        s1 += if_written(a1, sa);
        s2 += if_written(a2, sa);
        s3 += if_written(a3, sa);
        s0 += if_written(b0, sb);
        s1 += if_written(b1, sb);
        s2 += if_written(b2, sb);
        s3 += if_written(b3, sb);
        s0 += if_written(c0, sc);
        s1 += if_written(c1, sc);
        s2 += if_written(c2, sc);
        s3 += if_written(c3, sc);
        s0 += if_written(d0, sd);
        s1 += if_written(d1, sd);
        s2 += if_written(d2, sd);
        s3 += if_written(d3, sd);
#if NORMAL_DEPTH_GRADS
        s4 += if_written(record_vec4(sa, 4u), sa);
        s4 += if_written(record_vec4(sb, 4u), sb);
        s4 += if_written(record_vec4(sc, 4u), sc);
        s4 += if_written(record_vec4(sd, 4u), sd);
#endif
    }
    var g: RasterGrads;
    g.v_plane = RayPlane(vec3<f32>(s0.x, s0.z, s1.x), vec3<f32>(s2.x, s2.z, s3.x), vec3<f32>(s0.y, s0.w, s1.y));
    g.v_opacity = s1.z;
    g.v_mu2d = vec2<f32>(s3.z, s1.w);
    let tail = vec4<f32>(s2.y, s2.w, s3.y, s3.w);
#if NORMAL_DEPTH_GRADS
    g.v_normal = tail.xyz;
    g.v_depth = tail.w;
    g.v_color = s4;
#else
    g.v_normal = vec3<f32>(0.0);
    g.v_depth = 0.0;
    g.v_color = tail;
#endif
    return g;
}
#else
fn raster_grads(i: u32) -> RasterGrads {
    let g = i * 16u;
    var r: RasterGrads;
    r.v_plane = RayPlane(vec3<f32>(v_proj[g], v_proj[g + 1u], v_proj[g + 2u]),
                         vec3<f32>(v_proj[g + 3u], v_proj[g + 4u], v_proj[g + 5u]),
                         vec3<f32>(v_proj[g + 6u], v_proj[g + 7u], v_proj[g + 8u]));
    r.v_mu2d = vec2<f32>(v_proj[g + 9u], v_proj[g + 10u]);
    r.v_opacity = v_proj[g + 11u];
#if COLOR_IN_PROJ
    r.v_normal = vec3<f32>(0.0);
    r.v_depth = 0.0;
    r.v_color = vec4<f32>(v_proj[g + 12u], v_proj[g + 13u], v_proj[g + 14u], v_proj[g + 15u]);
#else
    r.v_normal = vec3<f32>(v_proj[g + 12u], v_proj[g + 13u], v_proj[g + 14u]);
    r.v_depth = v_proj[g + 15u];
    r.v_color = vec4<f32>(0.0);   // in v_colors, written by the rasterizer
#endif
    return r;
}
#endif

// Gradient of R(q / |q|) with respect to q, given dL/dR (columns of v_r are dL/d(column)).
fn quat_backward(q_in: vec4<f32>, v_r: mat3x3<f32>) -> vec4<f32> {
    let inv_norm = inverseSqrt(dot(q_in, q_in));
    let q = q_in * inv_norm;
    let w = q.x;
    let x = q.y;
    let y = q.z;
    let z = q.w;
    // g[r][c] = dL/dR[r][c]; WGSL matrices are column-major: v_r[c][r].
    let g00 = v_r[0][0]; let g01 = v_r[1][0]; let g02 = v_r[2][0];
    let g10 = v_r[0][1]; let g11 = v_r[1][1]; let g12 = v_r[2][1];
    let g20 = v_r[0][2]; let g21 = v_r[1][2]; let g22 = v_r[2][2];
    let v_unit = 2.0 * vec4<f32>(
        -z * g01 + y * g02 + z * g10 - x * g12 - y * g20 + x * g21,
        y * g01 + z * g02 + y * g10 - 2.0 * x * g11 - w * g12 + z * g20 + w * g21 - 2.0 * x * g22,
        -2.0 * y * g00 + x * g01 + w * g02 + x * g10 + z * g12 - w * g20 + z * g21 - 2.0 * y * g22,
        -2.0 * z * g00 - w * g01 + x * g02 + w * g10 - 2.0 * z * g11 + y * g12 + x * g20 + y * g21,
    );
    // Normalisation: d(q/|q|)/dq = (I - q q^T) / |q|.
    return (v_unit - q * dot(q, v_unit)) * inv_norm;
}

#if WORK_QUEUE
@group(0) @binding(14) var<storage, read_write> work_queue: array<atomic<u32>>;
#endif
#include "common/surfel_pass_main.wgsl"

// The gradients of surfel i (none past the end).
fn surfel_work(i: u32) {
    if i >= params.num_surfels {
        return;
    }
    let culled = tile_counts[i] == 0u;
#if GRAD_RECORDS
    // record_base is written only for listed surfels; a culled one has no records.
    var rg: RasterGrads;
    if !culled {
        rg = raster_grads(i);
    }
#else
    let rg = raster_grads(i);
#endif
#if COLORS_OUT
    for (var c = 0u; c < CHANNELS; c++) {
        v_colors[i * CHANNELS + c] = select(component4(rg.v_color, c), 0.0, culled);
    }
#endif
    if culled {
        v_means[3u * i] = 0.0;
        v_means[3u * i + 1u] = 0.0;
        v_means[3u * i + 2u] = 0.0;
        for (var k = 0u; k < 4u; k++) {
            v_quats[4u * i + k] = 0.0;
        }
        v_scales[2u * i] = 0.0;
        v_scales[2u * i + 1u] = 0.0;
        v_opacities[i] = 0.0;
        return;
    }
    // Recompute the forward projection (project_fwd.wgsl).
    let mean = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let r0 = params.w2c_r0;
    let r1 = params.w2c_r1;
    let r2 = params.w2c_r2;
    let mu_c = vec3<f32>(dot(r0.xyz, mean) + r0.w, dot(r1.xyz, mean) + r1.w, dot(r2.xyz, mean) + r2.w);
    let q = vec4<f32>(quats[4u * i], quats[4u * i + 1u], quats[4u * i + 2u], quats[4u * i + 3u]);
    let rot = quat_to_mat3(q);
    let w2c = transpose(mat3x3<f32>(r0.xyz, r1.xyz, r2.xyz));
    let s = vec2<f32>(scales[2u * i], scales[2u * i + 1u]);
    let axis_u = w2c * rot[0];
    let axis_v = w2c * rot[1];
    let n_raw = w2c * rot[2];
    let flip = select(1.0, -1.0, dot(n_raw, mu_c) > 0.0);
    let k = transpose(mat3x3<f32>(params.k_r0.xyz, params.k_r1.xyz, params.k_r2.xyz));
    let c0 = k * (axis_u * s.x);
    let c1 = k * (axis_v * s.y);
    let c2 = k * mu_c;
    let t0 = vec3<f32>(c0.x, c1.x, c2.x);
    let t1 = vec3<f32>(c0.y, c1.y, c2.y);
    let t2 = vec3<f32>(c0.z, c1.z, c2.z);
    let denom = t2.x * t2.x + t2.y * t2.y - t2.z * t2.z;
    let f = vec3<f32>(1.0, 1.0, -1.0) / denom;
    let mu2d = vec2<f32>(dot(f, t0 * t2), dot(f, t1 * t2));

    // The ray plane about the reference point c that projection chose (ray_plane.wgsl), whose gradient
    // reaches the projected centre where the clamp left it alone (elsewhere no pixel's alpha depends on it).
    let c = ray_plane_reference(mu2d, params.image_size);
    let v_rows = ray_plane_backward(t0, t1, t2, c, rg.v_plane);
    var v_t0 = v_rows.t0;
    var v_t1 = v_rows.t1;
    var v_t2 = v_rows.t2;
    let v_mu2d = select(vec2<f32>(0.0), rg.v_mu2d, c == mu2d);
    let v_normal = rg.v_normal;
    let v_depth = rg.v_depth;

    // mu2d = (sum_j f_j T0j T2j, sum_j f_j T1j T2j), f = (1, 1, -1) / denom.
    v_t0 += v_mu2d.x * f * t2;
    v_t1 += v_mu2d.y * f * t2;
    v_t2 += v_mu2d.x * f * (t0 - 2.0 * mu2d.x * t2) + v_mu2d.y * f * (t1 - 2.0 * mu2d.y * t2);

    // T = K [c_u, c_v, mu_c] column by column: dL/dcolumn j = K^T (dL/dT)[:, j].
    let kt = transpose(k);
    let v_cu = kt * vec3<f32>(v_t0.x, v_t1.x, v_t2.x);
    let v_cv = kt * vec3<f32>(v_t0.y, v_t1.y, v_t2.y);
    var v_muc = kt * vec3<f32>(v_t0.z, v_t1.z, v_t2.z);
    v_muc.z += v_depth;
    let v_mean = transpose(w2c) * v_muc;

    let v_su = dot(axis_u, v_cu);
    let v_sv = dot(axis_v, v_cv);
    let r_t = transpose(w2c);
    let v_rot = mat3x3<f32>(r_t * v_cu * s.x, r_t * v_cv * s.y, r_t * v_normal * flip);
    let v_q = quat_backward(q, v_rot);

    v_means[3u * i] = v_mean.x;
    v_means[3u * i + 1u] = v_mean.y;
    v_means[3u * i + 2u] = v_mean.z;
    v_quats[4u * i] = v_q.x;
    v_quats[4u * i + 1u] = v_q.y;
    v_quats[4u * i + 2u] = v_q.z;
    v_quats[4u * i + 3u] = v_q.w;
    v_scales[2u * i] = v_su;
    v_scales[2u * i + 1u] = v_sv;
    v_opacities[i] = rg.v_opacity;
}
