// Backward rasterizer: one workgroup per tile, one thread per pixel. Each pixel replays its forward
// compositing back to front, starting from its final transmittance and last contributor, recovering
// T before each surfel as T_after / (1 - alpha). Per surfel it produces the gradients of the pixel's
// outputs with respect to the ray plane (p_ref, dp_dx, dp_dy: ProjectedSurfel; project_bwd.wgsl chains
// them to the ray transform T), the reference point, opacity, colour, normal and depth.
// Defines: CHANNELS, BATCH, FLOAT_ATOMICS, USE_SUBGROUPS (+ SG; that variant needs CHANNELS <= 4),
// ALPHA_GRADS (false when no loss reads the alpha image: its upstream is then zero, its terms dropped),
// NORMAL_DEPTH_GRADS (false when no loss reads the normal or depth images: their per-surfel gradients
// are then zero and neither summed nor scattered; the buffer entries stay zero), and GRAD_RECORDS
// (lavapipe, SG = 8: per-intersection gradient records instead of per-surfel atomics, see below; the tile
// walk of tile_walk_bwd.wgsl, one subgroup per tile, writes them, so it is this variant's entry point).
// WALK_LAYOUT (with TILE_WALK): the surfels' colour and normal-depth vec4s as the tile walks lay them out
// (surfel_texels.wgsl).
#include "render/rasterize_core.wgsl"
#include "render/grad_atomics.wgsl"

@group(0) @binding(6) var<storage, read> final_t: array<f32>;          // [H, W]
@group(0) @binding(7) var<storage, read> last_index: array<u32>;       // [H, W]
@group(0) @binding(8) var<storage, read> v_out_color: array<f32>;      // [H, W, CHANNELS]
#if ALPHA_GRADS
@group(0) @binding(9) var<storage, read> v_out_alpha: array<f32>;      // [H, W]
#endif
@group(0) @binding(10) var<storage, read> v_out_normal: array<f32>;    // [H, W, 3]
@group(0) @binding(11) var<storage, read> v_out_depth: array<f32>;     // [H, W]

// Gradients of one pixel with respect to one surfel's parameters.
struct SurfelGrad {
    v_p_ref: vec3<f32>,
    v_dp_dx: vec3<f32>,
    v_dp_dy: vec3<f32>,
    v_mu2d: vec2<f32>,   // the reference point's
    v_opacity: f32,
    v_nd: vec4<f32>,     // normal (xyz), depth (w)
}

// d alpha / d(p, mu2d, opacity) scaled by v_alpha, from an alpha evaluation (alpha_from() in
// rasterize_core.wgsl; the gradient reuses its terms). Branch-free for the subgroup path: zero where the
// alpha was clamped (it no longer depends on the surfel), v_p zero where sigma came from the 2D distance.
struct AlphaGrad {
    v_p: vec3<f32>,
    v_mu2d: vec2<f32>,
    v_opacity: f32,
}

fn alpha_backward(a: AlphaEval, v_alpha_in: f32) -> AlphaGrad {
    let v_alpha = select(0.0, v_alpha_in, a.raw < MAX_ALPHA);
    let v_sigma = -v_alpha * a.raw;
    // sigma_3d = |uv|^2 / 2 with uv = p.xy / p.z: d sigma / dp = (uv, -|uv|^2) / p.z.
    let f = v_sigma * a.inv_pz;
    var g: AlphaGrad;
    g.v_p = select(vec3<f32>(0.0), vec3<f32>(f * a.uv, -f * dot(a.uv, a.uv)), a.use_3d);
    g.v_mu2d = select(-2.0 * v_sigma * a.d, vec2<f32>(0.0), a.use_3d);
    g.v_opacity = v_alpha * a.e;
    return g;
}

#if !USE_SUBGROUPS
fn flush(sid: u32, g: SurfelGrad) {
    let b = sid * G_STRIDE;
    add_proj(b + G_P_REF, g.v_p_ref.x);
    add_proj(b + G_P_REF + 1u, g.v_p_ref.y);
    add_proj(b + G_P_REF + 2u, g.v_p_ref.z);
    add_proj(b + G_DP_DX, g.v_dp_dx.x);
    add_proj(b + G_DP_DX + 1u, g.v_dp_dx.y);
    add_proj(b + G_DP_DX + 2u, g.v_dp_dx.z);
    add_proj(b + G_DP_DY, g.v_dp_dy.x);
    add_proj(b + G_DP_DY + 1u, g.v_dp_dy.y);
    add_proj(b + G_DP_DY + 2u, g.v_dp_dy.z);
    add_proj(b + G_MU2D, g.v_mu2d.x);
    add_proj(b + G_MU2D + 1u, g.v_mu2d.y);
    add_proj(b + G_OPACITY, g.v_opacity);
#if NORMAL_DEPTH_GRADS
    add_proj(b + G_NORMAL, g.v_nd.x);
    add_proj(b + G_NORMAL + 1u, g.v_nd.y);
    add_proj(b + G_NORMAL + 2u, g.v_nd.z);
    add_proj(b + G_DEPTH, g.v_nd.w);
#endif
}
#endif

#if !USE_SUBGROUPS
var<workgroup> batch_ids: array<u32, BATCH>;
var<workgroup> tile_last: atomic<u32>;

// Intersections of the tile (`range`) to replay: up to the furthest last contributor of any of its
// pixels (`last`: this thread's), as batches behind every pixel's last contributor need no replay.
// Uniform across the workgroup; call from uniform control flow (barriers).
fn replay_count(range: vec2<u32>, lid: u32, last: u32) -> u32 {
    if lid == 0u {
        atomicStore(&tile_last, 0u);
    }
    workgroupBarrier();
    atomicMax(&tile_last, last);
    return min(range.y - range.x, workgroupUniformLoad(&tile_last));
}
#endif

// Up to 4 channels as a zero-padded vec4 (no private arrays; see the subgroup path below).
fn upstream_color4(p: u32) -> vec4<f32> {
    let base = p * CHANNELS;
    let last = CHANNELS - 1u;
    return vec4<f32>(v_out_color[base], select(0.0, v_out_color[base + min(1u, last)], CHANNELS > 1u),
                     select(0.0, v_out_color[base + min(2u, last)], CHANNELS > 2u),
                     select(0.0, v_out_color[base + min(3u, last)], CHANNELS > 3u));
}

#if USE_SUBGROUPS
// The subgroup variant (CPU drivers; at most 4 channels) gives each thread four pixels of the tile, in
// one column at rows y, y + 2, y + 4, y + 6 (tile_pixel_quad in rasterize_core.wgsl), so that a
// subgroup of 8 lanes covers a 4x8 pixel block instead of 4x2. Each hit's gradient is summed over the
// four pixels and then over the subgroup before the atomic adds, and on lavapipe those adds (one locked
// compare-exchange per value) dominate this pass: a surfel is flushed once per block it touches, and the
// blocks are 4x larger. The shuffles that pass a surfel between the lanes are shared by the four pixels
// too, so more pixels per thread make this pass faster.

// Replay state of one pixel (see the plain variant below for the quantities).
struct PixelReplay {
    px: vec2<f32>,
    T: f32,
    last: u32,
    v_col: vec4<f32>,
    v_a: f32,
    v_nd: vec4<f32>,
    behind: f32,   // what lies behind the current surfel, weighted by the upstream gradients (see replay_hit)
}

fn start_replay(pix: vec2<u32>) -> PixelReplay {
    let inside = pix.x < params.image_size.x && pix.y < params.image_size.y;
    let p = select(0u, pix.y * params.image_size.x + pix.x, inside);
    var r: PixelReplay;
    r.px = vec2<f32>(pix) + 0.5;
    r.T = select(1.0, final_t[p], inside);
    r.last = select(0u, last_index[p], inside);
    // Colours in one vec4 register: any dynamically indexed private array would be placed in per-lane
    // scratch memory by CPU drivers, making every access in the loop a gather. Below 4 channels colors4.w
    // holds the depth (DEPTH_IN_COLOR), which v_col.w = 0 cancels.
    r.v_col = select(vec4<f32>(0.0), upstream_color4(p), inside);
#if ALPHA_GRADS
    r.v_a = select(0.0, v_out_alpha[p], inside);
#else
    r.v_a = 0.0;   // no loss reads the alpha image (its upstream buffer is not bound)
#endif
    r.behind = r.T * dot(r.v_col, background4());   // the background's share of the colour (none of alpha)
#if NORMAL_DEPTH_GRADS
    r.v_nd = select(vec4<f32>(0.0), vec4<f32>(v_out_normal[3u * p], v_out_normal[3u * p + 1u],
                                                 v_out_normal[3u * p + 2u], v_out_depth[p]), inside);
#else
    r.v_nd = vec4<f32>(0.0);  // no loss reads normal or depth (their upstream buffers are not bound)
#endif
    return r;
}

// A surfel's gradient summed over a thread's four pixels, with the ray-transform part still as d/dp
// (see main: the ray plane's gradient is formed once per thread from these sums).
struct QuadGrad {
    v_p: vec3<f32>,      // sum over the pixels of d loss / dp
    v_p_dy: vec3<f32>,   // the same, each pixel's weighted by its row offset dy from the first pixel
    v_mu2d: vec2<f32>,
    v_opacity: f32,
    v_nd: vec4<f32>,
}

// The ray plane's gradient (d loss / d(p_ref, dp_dx, dp_dy)) of a thread's four pixels from their sums `q`:
// p = p_ref + d.x dp_dx + d.y dp_dy, the pixels share d.x (`d`: the first pixel's offset from the
// reference point) and lie dy rows below the first.
fn quad_plane_grad(q: QuadGrad, d: vec2<f32>) -> RayPlane {
    return RayPlane(q.v_p, d.x * q.v_p, d.y * q.v_p + q.v_p_dy);
}

// Step pixel `r` (the thread's pixel k, 0-3) back over a surfel with alpha terms `ae`, normal and depth
// `nd`, colour `col`, local intersection index `idx`: adds the pixel's gradient to `q` and returns its
// colour gradient; `hit` says whether the surfel contributed.
fn replay_hit(ae: AlphaEval, k: u32, nd: vec4<f32>, col: vec4<f32>, idx: u32, r: ptr<function, PixelReplay>,
              q: ptr<function, QuadGrad>, hit: ptr<function, bool>) -> vec4<f32> {
    let alpha = min(MAX_ALPHA, ae.raw);
    let contrib = idx < (*r).last && alpha >= ALPHA_THRESHOLD;
    let ra = 1.0 / (1.0 - alpha);
    let T_i = (*r).T * ra;
    let w = select(0.0, alpha * T_i, contrib);
    // The upstream-weighted output of this surfel (see `behind` in main's plain variant).
    var g = dot((*r).v_col, col);
#if ALPHA_GRADS
    g += (*r).v_a;
#endif
#if NORMAL_DEPTH_GRADS
    g += dot((*r).v_nd, nd);
    (*q).v_nd += w * (*r).v_nd;
#endif
    let v_alpha = T_i * g - ra * (*r).behind;
    let ag = alpha_backward(ae, select(0.0, v_alpha, contrib));
    (*q).v_p += ag.v_p;
    if k != 0u {   // constant after inlining
        (*q).v_p_dy += f32(k * ROW_STEP.y) * ag.v_p;
    }
    (*q).v_mu2d += ag.v_mu2d;
    (*q).v_opacity += ag.v_opacity;
    (*r).behind += w * g;
    (*r).T = select((*r).T, T_i, contrib);
    *hit = contrib;
    return w * (*r).v_col;
}

#if GRAD_RECORDS
// Gradient records: one per intersection that some pixel took, at its place in the tile-sorted list
// (found per surfel through the slots, see tile_walk_bwd.wgsl), RECORD_VEC2S vec2s each, summed per
// surfel by project_bwd.wgsl. The tile
// walk (tile_walk_bwd.wgsl, the only variant that writes them) stores each record once, from the one
// subgroup that replays the tile: only on lavapipe (RasterOptions.grad_records; GPUs, whose subgroups run
// concurrently, keep per-surfel atomics). On lavapipe a float atomic per value is a per-lane loop of
// locked compare-and-exchanges, a large share of this pass; plain stores into records cost less even
// with the pass that sums them. The records sit at the intersection's tile-sorted place, where the walk
// writes them in order (scattered stores at the emission index cost the walk more than they saved
// project_bwd), with the slots that find them written by the walk itself (tile_walk_bwd.wgsl). The sums
// run in a fixed order, so the gradients are the same on every run, also under load.
#if RECORD_TEXELS
// The records as rgba32float texels, RECORD_VEC2S / 2 per record (texel_at; gma/render/surfel_texels.py): project_bwd's scattered reads gather for all lanes at once.
@group(0) @binding(23) var record_texels: texture_storage_2d<rgba32float, write>;
#else
@group(0) @binding(12) var<storage, read_write> records: array<vec2<f32>>;   // [isects, RECORD_VEC2S]
#endif

#if NORMAL_DEPTH_GRADS
const RECORD_VEC2S: u32 = 10u;   // V0-15 as below, then the colours 0-3
#else
const RECORD_VEC2S: u32 = 8u;    // V0-15 (the colours in V12-15)
#endif

#endif

#if !GRAD_RECORDS
// Add a hit's gradient totals over the subgroup to surfel `sid`'s gradients: a, b, c (the packed
// projection values, see proj_component), d (normal, depth), e (colours), one lane's share each.
// Butterfly sums over the subgroup: on CPU drivers subgroupAdd is far slower than log2(SG) xor-shuffles
// of packed vec4s.
fn flush_butterfly(sid: u32, a_in: vec4<f32>, b_in: vec4<f32>, c_in: vec4<f32>, d_in: vec4<f32>,
                   e_in: vec4<f32>, sg_lane: u32) {
    var a = a_in;
    var b = b_in;
    var c = c_in;
    var d = d_in;
    var e = e_in;
    for (var off = SG / 2u; off > 0u; off >>= 1u) {
        a += subgroupShuffleXor(a, off);
        b += subgroupShuffleXor(b, off);
        c += subgroupShuffleXor(c, off);
#if NORMAL_DEPTH_GRADS
        d += subgroupShuffleXor(d, off);
#endif
        e += subgroupShuffleXor(e, off);
    }
    // Every lane holds the totals (butterfly); lane i adds value i, i + SG, ... Lavapipe runs each
    // atomic as a loop over the lanes, so one lane adding all 15-19 values paid (as far as we can tell)
    // that loop 8 times per value with one lane active; spread, each loop does up to 8 adds.
    // Values are picked by selects (an indexed private array would go to scratch). Same adds,
    // bit-identical gradients, and faster than the lane-0 flush.
    // Without normal and depth gradients their slots (12-15) carry the colour gradients (copied out by
    // project_bwd): 15 values in two rounds of adds instead of three.
#if NORMAL_DEPTH_GRADS
    let tail = d;
#else
    let tail = e;   // the colour gradients, in the normal and depth slots
#endif
    for (var i0 = 0u; i0 < PROJ_VALUES; i0 += SG) {
        let i = i0 + sg_lane;
        let v = proj_component(i, a, b, c, tail);
        if i < PROJ_VALUES {
            add_proj(sid * G_STRIDE + i, v);
        }
    }
#if NORMAL_DEPTH_GRADS
    for (var i0 = 0u; i0 < CHANNELS; i0 += SG) {
        let i = i0 + sg_lane;
        let v = component4(e, i);
        if i < CHANNELS {
            add_color(sid * CHANNELS + i, v);
        }
    }
#endif
}

// flush_butterfly for 8 lanes: a reduce-scatter instead of an all-reduce, as each lane adds only a few
// totals. The 16 projection values (V0-3 = a, V4-7 = b, V8-11 = c, V12-15 = `tail`: the normal and
// depth gradients, or without those the colours): each round halves what a lane keeps and sends the
// other half to its partner, 8 + 4 + 2 scalar shuffles instead of 3 x 16, and lane l ends with the
// totals of V[l] and V[l + 8]. With normal and depth gradients the colours (`e`) follow in 2 + 1 + 1
// instead of 3 x 4. The partners add the same operands in the same order (own + partner's) as the
// butterfly, so the totals and the gradients are bit-identical.
fn flush_scattered8(sid: u32, a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, tail: vec4<f32>, e: vec4<f32>,
                    sg_lane: u32) {
    let e_total = scatter_colors8(e, sg_lane);
    let slot0 = value_slot(sg_lane);
    let slot1 = value_slot(sg_lane + 8u);
    let t = scatter16(a, b, c, tail, sg_lane);
    add_proj(sid * G_STRIDE + slot0, t.x);
    if slot1 < PROJ_VALUES {
        add_proj(sid * G_STRIDE + slot1, t.y);
    }
#if NORMAL_DEPTH_GRADS
    // Lanes 0, 2, 4, 6 hold the totals of colours 0-3 (scatter_colors8).
    let ch = sg_lane >> 1u;
    if (sg_lane & 1u) == 0u && ch < CHANNELS {
        add_color(sid * CHANNELS + ch, e_total);
    }
#endif
}
#endif

// Totals over 8 lanes of V0-15 (V0-3 = a, V4-7 = b, V8-11 = c, V12-15 = d), reduce-scattered: lane l
// gets those of V[l] (.x) and V[l + 8] (.y). Rounds over lane bits 2, 1, 0, as the butterfly's.
fn scatter16(a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, d: vec4<f32>, sg_lane: u32) -> vec2<f32> {
    let hi2 = (sg_lane & 4u) != 0u;   // keep V[4 hi2 + 0..3] and V[8 + 4 hi2 + 0..3]
    let r0 = select(a, b, hi2) + subgroupShuffleXor(select(b, a, hi2), 4u);
    let r1 = select(c, d, hi2) + subgroupShuffleXor(select(d, c, hi2), 4u);
    let hi1 = (sg_lane & 2u) != 0u;   // then the pair (lane & 6) + 0..1 of each
    let lo_pairs = vec4<f32>(r0.xy, r1.xy);
    let hi_pairs = vec4<f32>(r0.zw, r1.zw);
    let r2 = select(lo_pairs, hi_pairs, hi1) + subgroupShuffleXor(select(hi_pairs, lo_pairs, hi1), 2u);
    let hi0 = (sg_lane & 1u) != 0u;   // then the one value: V[lane], V[lane + 8]
    return select(r2.xz, r2.yw, hi0) + subgroupShuffleXor(select(r2.yw, r2.xz, hi0), 1u);
}

// Totals over 8 lanes of the four colours in e, reduce-scattered: lane l gets that of colour l / 2
// (lane bits 2 and 1 pick it; lanes l and l ^ 1 end equal). Rounds over lane bits 2, 1, 0, as the
// butterfly's. Unused (constant 0) without normal and depth gradients.
fn scatter_colors8(e: vec4<f32>, sg_lane: u32) -> f32 {
#if NORMAL_DEPTH_GRADS
    let hi2 = (sg_lane & 4u) != 0u;   // keep colours 2 hi2 + 0..1
    let r = select(e.xy, e.zw, hi2) + subgroupShuffleXor(select(e.zw, e.xy, hi2), 4u);
    let hi1 = (sg_lane & 2u) != 0u;   // then colour 2 hi2 + hi1
    let v = select(r.x, r.y, hi1) + subgroupShuffleXor(select(r.y, r.x, hi1), 2u);
    return v + subgroupShuffleXor(v, 1u);
#else
    return 0.0;
#endif
}

// The G_* slot (see proj_component) of value V[j] of flush_scattered8: the vectors' xyz are the ray
// plane's p_ref, dp_dx, dp_dy, a.w the opacity, b.w and c.w the reference point; V12-15 stay (the tail: normal and depth, or the colours).
fn value_slot(j: u32) -> u32 {
    let v = j >> 2u;
    let w_slot = select(select(11u, 9u, v == 1u), 10u, v == 2u);
    return select(select(3u * v + (j & 3u), w_slot, (j & 3u) == 3u), j, j >= 12u);
}

#if GRAD_RECORDS
#include "render/tile_walk_bwd.wgsl"
#else
@compute @workgroup_size(64)   // RASTER_THREADS
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32,
        @builtin(subgroup_invocation_id) sg_lane: u32, @builtin(subgroup_id) sg_id: u32) {
    let tile = wg.y * params.tile_grid.x + wg.x;
    let pix = wg.xy * TILE_SIZE + tile_pixel_quad(lid);
    var pa = start_replay(pix);
    var pb = start_replay(pix + ROW_STEP);
    var pc = start_replay(pix + 2u * ROW_STEP);
    var pd = start_replay(pix + 3u * ROW_STEP);
    let last = max(max(pa.last, pb.last), max(pc.last, pd.last));

    let range = ranges[tile];
    let tile_px = pix % TILE_SIZE;
    let my_blocks = lanes_or(quad_blocks(tile_px));
    // Each subgroup replays the intersections before its furthest last contributor on its own, with no
    // barriers (see composite_quad in rasterize_core.wgsl, which also explains the hit list).
    let count = min(range.y - range.x, lanes_max(last));
    let num_batches = ceil_div(count, BATCH);
    let row = sg_id * (BATCH + SG);
    for (var bi = 0u; bi < num_batches; bi++) {
        let b = num_batches - 1u - bi;
        let start = b * BATCH;   // local index of the batch's first intersection
        let m = min(BATCH, count - start);
        // Surfels pass between lanes by shuffles.
        let num_hits = list_hits(range.x + start, m, my_blocks, row, sg_lane);
        for (var hh = 0u; hh < num_hits; hh += SG) {
            let h0 = num_hits - min(num_hits, hh + SG);   // this chunk covers list entries [h0, num_hits - hh)
            let n = num_hits - hh - h0;
            let mine_hit = hit_entries[row + min(h0 + sg_lane, num_hits - 1u)];
            let mine_slot = hit_slot(mine_hit);
            let mine_id = hit_surfel(mine_hit);
            // Field by field: the normal and depth are read only when their gradients are wanted (one
            // load of the whole surfel reads them always).
            let mine_p_ref = projected[mine_id].p_ref;
            let mine_dp_dx = projected[mine_id].dp_dx;
            let mine_dp_dy = projected[mine_id].dp_dy;
            let mine_col = load_color4(mine_id);   // in the layout projection wrote (surfel_texels.wgsl)
            for (var kk = 0u; kk < n; kk++) {
                let k = n - 1u - kk;               // back to front
                let idx = start + subgroupShuffle(mine_slot, k);   // local intersection index in the tile
#if NORMAL_DEPTH_GRADS
                let nd = subgroupShuffle(load_normal_depth(mine_id), k);
#else
                let nd = vec4<f32>(0.0);  // only ever multiplied by the zero v_nd: not worth a shuffle
#endif
                let s = ProjectedSurfel(subgroupShuffle(mine_p_ref, k), subgroupShuffle(mine_dp_dx, k),
                                        subgroupShuffle(mine_dp_dy, k), nd);
                let col = subgroupShuffle(mine_col, k);
                let sid = subgroupShuffle(mine_id, k);
                // Explicitly initialised: naga hoists an uninitialised `var` out of the loop without re-zeroing it.
                var q = QuadGrad(vec3<f32>(0.0), vec3<f32>(0.0), vec2<f32>(0.0), 0.0, vec4<f32>(0.0));
                var hit_a = false;
                var hit_b = false;
                var hit_c = false;
                var hit_d = false;
                let ca = column_alpha(s, pa.px);   // the forward's alpha arithmetic (composite_quad)
                let g_col = replay_hit(quad_alpha(s, ca, 0u), 0u, nd, col, idx, &pa, &q, &hit_a)
                          + replay_hit(quad_alpha(s, ca, 1u), 1u, nd, col, idx, &pb, &q, &hit_b)
                          + replay_hit(quad_alpha(s, ca, 2u), 2u, nd, col, idx, &pc, &q, &hit_c)
                          + replay_hit(quad_alpha(s, ca, 3u), 3u, nd, col, idx, &pd, &q, &hit_d);
                if any_lane(hit_a || hit_b || hit_c || hit_d) {
                    let pg = quad_plane_grad(q, ca.d);   // over the four pixels at once
                    let a = vec4<f32>(pg.p_ref, q.v_opacity);
                    let b = vec4<f32>(pg.dp_dx, q.v_mu2d.x);
                    let c = vec4<f32>(pg.dp_dy, q.v_mu2d.y);
#if NORMAL_DEPTH_GRADS
                    let tail = q.v_nd;
#else
                    let tail = g_col;   // the colour gradients, in the normal and depth slots
#endif
                    if SG == 8u {   // constant after inlining
                        flush_scattered8(sid, a, b, c, tail, g_col, sg_lane);
                    } else {
                        flush_butterfly(sid, a, b, c, q.v_nd, g_col, sg_lane);
                    }
                }
            }
        }
    }
}

#endif

#if NORMAL_DEPTH_GRADS
const PROJ_VALUES: u32 = 16u;
#else
const PROJ_VALUES: u32 = 12u + CHANNELS;   // colour gradients in the normal and depth slots
#endif

// Projection gradient value `i` (G_* layout) from the packed subgroup totals (see main); `d` fills
// slots 12-15 (normal and depth, or the colours when there are no normal/depth gradients).
fn proj_component(i: u32, a: vec4<f32>, b: vec4<f32>, c: vec4<f32>, d: vec4<f32>) -> f32 {
    var v = a.x;                      // G_P_REF
    v = select(v, a.y, i == 1u);
    v = select(v, a.z, i == 2u);
    v = select(v, b.x, i == 3u);      // G_DP_DX
    v = select(v, b.y, i == 4u);
    v = select(v, b.z, i == 5u);
    v = select(v, c.x, i == 6u);      // G_DP_DY
    v = select(v, c.y, i == 7u);
    v = select(v, c.z, i == 8u);
    v = select(v, b.w, i == 9u);      // G_MU2D
    v = select(v, c.w, i == 10u);
    v = select(v, a.w, i == 11u);     // G_OPACITY
    v = select(v, d.x, i == 12u);     // G_NORMAL
    v = select(v, d.y, i == 13u);
    v = select(v, d.z, i == 14u);
    v = select(v, d.w, i == 15u);     // G_DEPTH
    return v;
}
#else
@compute @workgroup_size(256)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let pix = wg.xy * TILE_SIZE + tile_pixel(lid);
    let inside = pix.x < params.image_size.x && pix.y < params.image_size.y;
    let tile = wg.y * params.tile_grid.x + wg.x;
    let px = vec2<f32>(pix) + 0.5;
    let p = select(0u, pix.y * params.image_size.x + pix.x, inside);

    // Per-pixel state of the replay. Every output f of the pixel (colour channels, alpha, normal, depth)
    // is sum_i w_i f_i (+ T_final bg for colour), so d f / d alpha_i = T_i f_i - behind_f / (1 - alpha_i),
    // where behind_f, what lies behind surfel i, is the sum of w_j f_j over later surfels j (plus T_final
    // bg). The loss needs only sum_f v_f d f / d alpha_i, in which those sums appear only as
    // sum_f v_f behind_f: one scalar, `behind`, instead of one value per output.
    var T = select(1.0, final_t[p], inside);
    let last = select(0u, last_index[p], inside);
    var v_col: array<vec4<f32>, CHUNKS>;
    var behind = 0.0;
    for (var c = 0u; c < CHANNELS; c++) {
        let v = select(0.0, v_out_color[p * CHANNELS + c], inside);
        v_col[c / 4u][c % 4u] = v;
        behind += v * T * background[c];
    }
#if ALPHA_GRADS
    let v_a = select(0.0, v_out_alpha[p], inside);
#else
    let v_a = 0.0;
#endif
#if NORMAL_DEPTH_GRADS
    let v_nd = select(vec4<f32>(0.0), vec4<f32>(v_out_normal[3u * p], v_out_normal[3u * p + 1u],
                                                   v_out_normal[3u * p + 2u], v_out_depth[p]), inside);
#else
    let v_nd = vec4<f32>(0.0);  // no loss reads normal or depth (their upstream buffers are not bound)
#endif

    let range = ranges[tile];
    let count = replay_count(range, lid, last);
    let num_batches = ceil_div(count, BATCH);
    // Only the intersections before the tile's furthest last contributor matter.
    for (var bi = 0u; bi < num_batches; bi++) {
        let b = num_batches - 1u - bi;
        let start = b * BATCH;   // local index of the batch's first intersection
        workgroupBarrier();
        if lid < BATCH && start + lid < count {
            let sid = isect_ids[range.x + start + lid] & SURFEL_ID_MASK;
            batch_ids[lid] = sid;
            stage_surfel(lid, sid);
        }
        workgroupBarrier();
        let m = min(BATCH, count - start);
        for (var jj = 0u; jj < m; jj++) {
            let j = m - 1u - jj;
            let idx = start + j;
            if idx >= last {
                continue;
            }
            let s = batch_surf[j];
            // surfel_alpha() of the forward, keeping the terms the gradient needs.
            let d = reference_offset(s, px);
            let ae = alpha_from(s, ray_plane_at(s, d), d);
            let alpha = min(MAX_ALPHA, ae.raw);
            if alpha < ALPHA_THRESHOLD {
                continue;
            }
            let ra = 1.0 / (1.0 - alpha);
            let T_i = T * ra;
            let w = alpha * T_i;
            var g_out = v_a + dot(v_nd, s.normal_depth);   // the surfel's upstream-weighted output
            let sid = batch_ids[j];
            for (var c = 0u; c < CHUNKS; c++) {
                g_out += dot(v_col[c], batch_color[j * CHUNKS + c]);
                for (var e = 0u; e < 4u; e++) {
                    if 4u * c + e < CHANNELS {
                        add_color(sid * CHANNELS + 4u * c + e, w * v_col[c][e]);
                    }
                }
            }
            // Explicitly initialised: naga hoists an uninitialised `var` out of the loop without re-zeroing it.
            var g = SurfelGrad(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec2<f32>(0.0), 0.0, vec4<f32>(0.0));
            let ag = alpha_backward(ae, T_i * g_out - ra * behind);
            g.v_p_ref = ag.v_p;
            g.v_dp_dx = d.x * ag.v_p;
            g.v_dp_dy = d.y * ag.v_p;
            g.v_mu2d = ag.v_mu2d;
            g.v_opacity = ag.v_opacity;
            g.v_nd = w * v_nd;
            flush(sid, g);
            behind += w * g_out;
            T = T_i;
        }
    }
}
#endif
