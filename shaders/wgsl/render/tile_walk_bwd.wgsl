// The backward rasterizer's entry point for 8-lane CPU drivers with gradient records (GRAD_RECORDS,
// which needs the forward's TILE_WALK: lavapipe): one subgroup replays the whole 16x16 tile, as
// tile_walk_fwd.wgsl composites it. Included by rasterize_bwd.wgsl, whose replay arithmetic (replay_hit,
// quad_alpha) it uses.
//
// It walks the tile's list once, back to front, reads each intersection's surfel once (one per lane,
// 8 at a time, passed around by shuffles), and replays it in every block of the tile where some pixel
// took it in the forward (used_blocks, written by the forward's walk), keeping the eight blocks'
// replay states (BlockReplay) in its registers and stack. The surfel's gradient is summed over the
// lane's pixels of all those blocks, then over the lanes (reduce-scatter), and written to its record
// once, with plain stores: no other subgroup writes it. The per-subgroup variant (main in
// rasterize_bwd.wgsl, with atomics only) flushes it once per block it reaches, and every subgroup scans
// the whole tile list; an intersection reaches between two and three blocks on the standard scene.
// The gradients' sums run in another order than there (within float rounding; the same on every run).
// Which blocks to replay is the forward's used blocks (a used block has a pixel that took the hit), not
// the block bits: the block bits allow many replays that add only zeros, most of all at a fit's small
// image sizes, and recording the used blocks costs the forward next to nothing. The same test replaces
// a vote before a record's store (a hit with used blocks has a pixel that took it).

// An intersection's record goes to its place in the tile-sorted list, so that the walk writes records
// in order. project_bwd.wgsl finds a surfel's records through the slots: by emission index
// (record_base[surfel] + its number within its surfel's list, above RECORD_KEY_SHIFT in its key, so a
// surfel's slots are consecutive), the record's place + 1, or 0 where the walk stored no record (the
// slots are cleared before the pass; no record is, nor need be). Records at the emission index would
// make this pass's stores scattered (one cache miss each); here project_bwd's reads are scattered
// instead, which costs it less than the walk saves.
@group(0) @binding(16) var<storage, read> isect_keys: array<u32>;   // tile-sorted keys
@group(0) @binding(17) var<storage, read> record_base: array<u32>;  // [N] by surfel id
@group(0) @binding(22) var<storage, read_write> record_slots: array<u32>;  // [isects] by emission index
// Per intersection of the tile list, the blocks where some pixel took the surfel in the forward
// (USED_BLOCKS in tile_walk_fwd.wgsl). Elsewhere its replay would change no state and add only zeros:
// no pixel there has it before its last contributor with alpha >= 1/255.
@group(0) @binding(19) var<storage, read> used_blocks: array<u32>;

struct BlockReplay {
    a: PixelReplay,
    b: PixelReplay,
    c: PixelReplay,
    d: PixelReplay,
}

// A hit's gradient over the lane's pixels of every block it reached. p = p_ref + d.x dp_dx + d.y dp_dy
// (ProjectedSurfel), so the ray plane's gradients are the sums of d loss / dp, unweighted and weighted by
// the pixels' offsets d from the reference point: the record takes them as they are, and project_bwd
// turns their sums over a surfel's records into d loss / dT once per surfel (forming d loss / dT per hit
// would take six cross products per hit).
struct HitTotals {
    v_p: vec3<f32>,      // sum of d loss / dp over the lane's pixels of the blocks: d loss / dp_ref
    v_p_x: vec3<f32>,    // the same, each pixel's weighted by its offset d.x: d loss / ddp_dx
    v_p_y: vec3<f32>,    // ... and by its d.y: d loss / ddp_dy
    v_mu2d: vec2<f32>,
    v_opacity: f32,
    nd: vec4<f32>,
    e: vec4<f32>,
}

fn start_block_replay(origin: vec2<u32>, g: u32, sg_lane: u32) -> BlockReplay {
    let pix = block_first_pixel(origin, g, sg_lane);
    var r: BlockReplay;
    r.a = start_replay(pix);
    r.b = start_replay(pix + ROW_STEP);
    r.c = start_replay(pix + 2u * ROW_STEP);
    r.d = start_replay(pix + 3u * ROW_STEP);
    return r;
}

// The furthest last contributor of this lane's pixels in block r (local intersections before it).
fn block_last(r: BlockReplay) -> u32 {
    return max(max(r.a.last, r.b.last), max(r.c.last, r.d.last));
}

// Replay surfel `s` in one block (the per-subgroup variant's hit step) and add its gradient to `t`.
// The states are copied into values of this call and back (a pointer to a member of *r made naga
// 29 panic while writing SPIR-V).
fn replay_block(s: ProjectedSurfel, nd: vec4<f32>, col: vec4<f32>, idx: u32, r: ptr<function, BlockReplay>,
                t: ptr<function, HitTotals>) {
    var q = QuadGrad(vec3<f32>(0.0), vec3<f32>(0.0), vec2<f32>(0.0), 0.0, vec4<f32>(0.0));
    var hit_a = false;   // whether each pixel took the surfel (replay_hit's; the used blocks say it here)
    var hit_b = false;
    var hit_c = false;
    var hit_d = false;
    var pa = (*r).a;
    var pb = (*r).b;
    var pc = (*r).c;
    var pd = (*r).d;
    let ca = column_alpha(s, pa.px);
    let g_col = replay_hit(quad_alpha(s, ca, 0u), 0u, nd, col, idx, &pa, &q, &hit_a)
              + replay_hit(quad_alpha(s, ca, 1u), 1u, nd, col, idx, &pb, &q, &hit_b)
              + replay_hit(quad_alpha(s, ca, 2u), 2u, nd, col, idx, &pc, &q, &hit_c)
              + replay_hit(quad_alpha(s, ca, 3u), 3u, nd, col, idx, &pd, &q, &hit_d);
    (*r).a = pa;
    (*r).b = pb;
    (*r).c = pc;
    (*r).d = pd;
    let pg = quad_plane_grad(q, ca.d);
    (*t).v_p += pg.p_ref;
    (*t).v_p_x += pg.dp_dx;
    (*t).v_p_y += pg.dp_dy;
    (*t).v_mu2d += q.v_mu2d;
    (*t).v_opacity += q.v_opacity;
    (*t).nd += q.v_nd;
    (*t).e += g_col;
}

// Write a hit's totals to record `rec` (its tile-sorted place): lane l stores V[l] and V[l + 8] (as
// flush_scattered8 adds them), totals over the lanes of the packed values a, b, c (the ray plane,
// opacity, reference point) and the tail.
fn store_record(rec: u32, t: HitTotals, sg_lane: u32) {
    let a = vec4<f32>(t.v_p, t.v_opacity);
    let b = vec4<f32>(t.v_p_x, t.v_mu2d.x);
    let c = vec4<f32>(t.v_p_y, t.v_mu2d.y);
#if NORMAL_DEPTH_GRADS
    let tail = t.nd;
#else
    let tail = t.e;   // the colour gradients, in the normal and depth slots
#endif
    let pair = scatter16(a, b, c, tail, sg_lane);
#if NORMAL_DEPTH_GRADS
    let e_total = scatter_colors8(t.e, sg_lane);   // lanes 0, 2, 4, 6: colours 0-3
#endif
#if RECORD_TEXELS
    // Texel j of the record is (V[2j], V[2j + 8], V[2j + 1], V[2j + 9]): lanes 2j and 2j + 1's pairs.
    // Lanes 0-3 store texels 0-3 (and, with normal and depth gradients, lane 4 the colours' texel).
    let j = sg_lane & 3u;
    var texel = vec4<f32>(subgroupShuffle(pair, 2u * j), subgroupShuffle(pair, 2u * j + 1u));
    var count = 4u;
#if NORMAL_DEPTH_GRADS
    // All four colours, zeros past the channels (the texture is never cleared).
    let colours = vec4<f32>(subgroupShuffle(e_total, 0u), subgroupShuffle(e_total, 2u),
                            subgroupShuffle(e_total, 4u), subgroupShuffle(e_total, 6u));
    texel = select(texel, select(vec4<f32>(0.0), colours, vec4<u32>(0u, 1u, 2u, 3u) < vec4<u32>(CHANNELS)),
                   sg_lane == 4u);
    count = 5u;
#endif
    if sg_lane < count {
        textureStore(record_texels, texel_at(rec * (RECORD_VEC2S / 2u) + sg_lane), texel);
    }
#else
    records[rec * RECORD_VEC2S + sg_lane] = pair;
#if NORMAL_DEPTH_GRADS
    let ch = sg_lane >> 1u;
    if (sg_lane & 1u) == 0u {   // all four, zeros past the channels: the records are not cleared
        records[rec * RECORD_VEC2S + 8u + (ch >> 1u)][ch & 1u] = select(0.0, e_total, ch < CHANNELS);
    }
#endif
#endif
}

#include "render/tile_walk_main.wgsl"

// Replay one tile with one subgroup.
fn walk(tile: u32, sg_lane: u32) {
    let origin = vec2<u32>(tile % params.tile_grid.x, tile / params.tile_grid.x) * TILE_SIZE;
    var r0 = start_block_replay(origin, 0u, sg_lane);
    var r1 = start_block_replay(origin, 1u, sg_lane);
    var r2 = start_block_replay(origin, 2u, sg_lane);
    var r3 = start_block_replay(origin, 3u, sg_lane);
    var r4 = start_block_replay(origin, 4u, sg_lane);
    var r5 = start_block_replay(origin, 5u, sg_lane);
    var r6 = start_block_replay(origin, 6u, sg_lane);
    var r7 = start_block_replay(origin, 7u, sg_lane);
    let range = ranges[tile];
    // The tile's furthest last contributor bounds the walk (subgroup-uniform).
    let furthest = max(max(max(block_last(r0), block_last(r1)), max(block_last(r2), block_last(r3))),
                       max(max(block_last(r4), block_last(r5)), max(block_last(r6), block_last(r7))));
    let count = min(range.y - range.x, subgroupBroadcast(lanes_max(furthest), 0u));
    for (var end = count; end > 0u; end -= min(end, SG)) {   // groups of SG, from the back
        let h0 = end - min(end, SG);
        let n = end - h0;
        let mine_at = range.x + h0 + min(sg_lane, n - 1u);
        let mine_id = isect_ids[mine_at];
        let mine_sid = mine_id & SURFEL_ID_MASK;
        let mine_used = used_blocks[mine_at];
        // Every lane stores (lanes past the group's end repeat the last one's store): a store under a
        // divergent condition is a loop with a branch per lane on lavapipe. A hit with used blocks gets
        // its record below.
        record_slots[record_base[mine_sid] + (isect_keys[mine_at] >> RECORD_KEY_SHIFT)] =
            select(0u, mine_at + 1u, mine_used != 0u);
        // Field by field, the normal and depth only when their gradients are wanted (see main).
        let mine_p_ref = load_projected_row(mine_sid, 0u);
        let mine_dp_dx = load_projected_row(mine_sid, 1u);
        let mine_dp_dy = load_projected_row(mine_sid, 2u);
        let mine_col = load_color4(mine_sid);
#if NORMAL_DEPTH_GRADS
        let mine_nd = load_normal_depth(mine_sid);
#endif
        for (var kk = 0u; kk < n; kk++) {
            let k = n - 1u - kk;   // back to front
            let idx = h0 + k;      // local intersection index in the tile
            // Lane 0's copy of the shuffled used blocks: uniform, so the branches below are jumps. (A
            // used block has a pixel whose last contributor lies at or behind this hit: live.)
            let blocks = subgroupBroadcast(subgroupShuffle(mine_used, k), 0u);
            if blocks != 0u {
#if NORMAL_DEPTH_GRADS
                let nd = subgroupShuffle(mine_nd, k);
#else
                let nd = vec4<f32>(0.0);  // only ever multiplied by the zero v_nd
#endif
                let s = ProjectedSurfel(subgroupShuffle(mine_p_ref, k), subgroupShuffle(mine_dp_dx, k),
                                        subgroupShuffle(mine_dp_dy, k), nd);
                let col = subgroupShuffle(mine_col, k);
                var t = HitTotals(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec2<f32>(0.0), 0.0,
                                  vec4<f32>(0.0), vec4<f32>(0.0));
                if (blocks & 1u) != 0u { replay_block(s, nd, col, idx, &r0, &t); }
                if (blocks & 2u) != 0u { replay_block(s, nd, col, idx, &r1, &t); }
                if (blocks & 4u) != 0u { replay_block(s, nd, col, idx, &r2, &t); }
                if (blocks & 8u) != 0u { replay_block(s, nd, col, idx, &r3, &t); }
                if (blocks & 16u) != 0u { replay_block(s, nd, col, idx, &r4, &t); }
                if (blocks & 32u) != 0u { replay_block(s, nd, col, idx, &r5, &t); }
                if (blocks & 64u) != 0u { replay_block(s, nd, col, idx, &r6, &t); }
                if (blocks & 128u) != 0u { replay_block(s, nd, col, idx, &r7, &t); }
                store_record(range.x + idx, t, sg_lane);
            }
        }
    }
}
