// Tiled front-to-back compositing shared by the buffer and texture variants of the forward rasterizer.
// One workgroup per 16x16 tile, one thread per pixel (four in the subgroup variant). The plain variant
// stages surfels BATCH at a time in workgroup memory and the tile stops early once every pixel is
// saturated; the subgroup variant's subgroups each walk the list on their own (see composite_quad).
// Defines: CHANNELS, BATCH, USE_SUBGROUPS and SG (the subgroup size) for the subgroup variant.
#include "common/render_types.wgsl"
#include "common/math.wgsl"
#include "render/block_bits.wgsl"
#include "render/ray_plane.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> projected: array<ProjectedSurfel>;   // [N]
#if !USE_SUBGROUPS
@group(0) @binding(2) var<storage, read> colors: array<f32>;                  // [N, CHANNELS]
#endif
@group(0) @binding(3) var<storage, read> isect_ids: array<u32>;   // tile-sorted; SURFEL_ID_MASK for the id
@group(0) @binding(4) var<storage, read> ranges: array<vec2<u32>>;            // [num_tiles]
@group(0) @binding(5) var<storage, read> background: array<f32>;              // [CHANNELS]
#if USE_SUBGROUPS
@group(0) @binding(15) var<storage, read> colors4: array<vec4<f32>>;          // [N] channels 0-3 (see DEPTH_IN_COLOR);
                                                                              // with WALK_LAYOUT the normal and depth
#if TILE_WALK
@group(0) @binding(18) var<storage, read> pixel_rows: array<u32>;              // [N] see tile_quads
#endif
#include "render/surfel_texels.wgsl"
// Per subgroup (row sg_id * (BATCH + SG)): the batch's intersections whose block mask meets the
// subgroup's blocks, each as its surfel id << 8 | its slot in the batch (hit_entry), then up to SG - 1
// entries of scratch (see list_hits). Only the subgroup's own lanes
// write and read its row, with no barrier between: a CPU driver runs a subgroup as one SIMD thread, in
// program order (this variant serves CPU drivers only).
var<workgroup> hit_entries: array<u32, (BATCH + SG) * (RASTER_THREADS / SG)>;

// The first four channels of the background, zeros past CHANNELS.
fn background4() -> vec4<f32> {
    let last = CHANNELS - 1u;
    return vec4<f32>(background[0], select(0.0, background[min(1u, last)], CHANNELS > 1u),
                     select(0.0, background[min(2u, last)], CHANNELS > 2u),
                     select(0.0, background[min(3u, last)], CHANNELS > 3u));
}

#if WORK_QUEUE
// The tile walks' queue of tiles (common/work_queue.wgsl): one workgroup per driver thread, each taking
// the next tile, in row order, until none is left.
@group(0) @binding(24) var<storage, read_write> work_queue: array<atomic<u32>>;
#include "common/work_queue.wgsl"
#endif

// Votes, ballots and reductions over the subgroup from xor-shuffles. Lavapipe runs subgroupBallot,
// subgroupAny, subgroupAll and subgroupOr/Max as a loop over the lanes whose counter and result live in
// memory (the frame of the coroutine that a shader with barriers becomes), which made the backward's one
// vote per hit a visible share of that pass. A xor-shuffle is one vector permute. Every lane ends with
// the same value; the votes take lane 0's (subgroupBroadcast at a constant lane is uniform), so that a
// branch on them is a real branch rather than masked work. Images and gradients are bit-identical to
// the subgroup builtins'.
fn lanes_or(v: u32) -> u32 {
    var r = v | subgroupShuffleXor(v, 1u);
    if SG > 2u { r |= subgroupShuffleXor(r, 2u); }   // constant conditions
    if SG > 4u { r |= subgroupShuffleXor(r, 4u); }
    if SG > 8u { r |= subgroupShuffleXor(r, 8u); }
    if SG > 16u { r |= subgroupShuffleXor(r, 16u); }
    if SG > 32u { r |= subgroupShuffleXor(r, 32u); }
    return r;
}

fn lanes_max(v: u32) -> u32 {
    var r = max(v, subgroupShuffleXor(v, 1u));
    if SG > 2u { r = max(r, subgroupShuffleXor(r, 2u)); }
    if SG > 4u { r = max(r, subgroupShuffleXor(r, 4u)); }
    if SG > 8u { r = max(r, subgroupShuffleXor(r, 8u)); }
    if SG > 16u { r = max(r, subgroupShuffleXor(r, 16u)); }
    if SG > 32u { r = max(r, subgroupShuffleXor(r, 32u)); }
    return r;
}

// Bit l set where lane l's `pred` holds (subgroupBallot(pred).x for SG <= 32).
fn lanes_ballot(pred: bool, sg_lane: u32) -> u32 {
    return lanes_or(select(0u, 1u << sg_lane, pred));
}

fn any_lane(pred: bool) -> bool {
    return subgroupBroadcast(lanes_or(u32(pred)), 0u) != 0u;
}

fn all_lanes(pred: bool) -> bool {
    return subgroupBroadcast(lanes_or(u32(!pred)), 0u) == 0u;
}

// A listed hit: surfel id (below 2^24) and slot in the batch (below BATCH <= 256) in one word.
fn hit_entry(isect_id: u32, slot: u32) -> u32 {
    return ((isect_id & SURFEL_ID_MASK) << 8u) | slot;
}

fn hit_slot(entry: u32) -> u32 {
    return entry & 0xffu;
}

fn hit_surfel(entry: u32) -> u32 {
    return entry >> 8u;
}

// Write, in slot order, the intersections among the `m` from list index `start` whose block bits
// (block_bits.wgsl) meet `blocks` into hit_entries[row..] (hit_entry: the id read here comes along, so the
// hit loops need not read it again: a gather is a loop over the lanes on lavapipe); returns their number
// (the same in every lane). Every lane stores, the misses just past the hits (where later hits or
// nothing read them): lavapipe runs a store under a divergent `if` as a loop over the lanes with a
// data-dependent branch per lane, which costs more than the store. Per-subgroup hit bitsets built while
// staging (so that listing reads a word per SG slots at a uniform address) cost in the build what the
// gathers saved.
fn list_hits(start: u32, m: u32, blocks: u32, row: u32, sg_lane: u32) -> u32 {
    var count = 0u;
    for (var j = 0u; j < m; j += SG) {
        let slot = j + sg_lane;
        let id = isect_ids[start + min(slot, m - 1u)];
        let hit = slot < m && (expand_block_bits(id >> SURFEL_ID_BITS) & blocks) != 0u;
        let hits = lanes_ballot(hit, sg_lane);
        let below = countOneBits(hits & ((1u << sg_lane) - 1u));
        let total = countOneBits(hits);
        hit_entries[row + count + select(total + sg_lane - below, below, hit)] = hit_entry(id, slot);
        count += total;
    }
    return count;
}
#endif

// Colours travel as CHUNKS vec4s per surfel (channels padded with zeros to a multiple of 4).
const CHUNKS: u32 = (CHANNELS + 3u) / 4u;
#if !USE_SUBGROUPS
var<workgroup> batch_surf: array<ProjectedSurfel, BATCH>;
var<workgroup> batch_color: array<vec4<f32>, BATCH * CHUNKS>;
var<workgroup> done_count: atomic<u32>;
#endif

struct PixelResult {
    color: array<vec4<f32>, CHUNKS>,  // without background; channel c is color[c / 4][c % 4]
    normal: vec3<f32>,
    depth: f32,
    transmittance: f32,            // final T
    last: u32,                     // one past the last contributing intersection index (0: none)
}

// Alpha of a surfel at a pixel (docs/design.md renderer contract, steps 2-3): the ray-splat intersection
// p = h_u x h_v with h_u = px.x T2 - T0, h_v = px.y T2 - T1 (evaluated in its linear form, ray_plane_at),
// and the 2D distance d as a floor. Every
// rasterizer, forward and backward, evaluates alpha through alpha_from() (from p and d), so that the
// backward replays the forward's alpha bit for bit.
struct AlphaEval {
    d: vec2<f32>,     // pixel centre - reference point (the projected centre where it is near the image)
    uv: vec2<f32>,    // p.xy / p.z (meaningful when use_3d)
    inv_pz: f32,      // 1 / p.z
    e: f32,           // exp(-sigma)
    raw: f32,         // opacity * e, before the clamp
    use_3d: bool,     // sigma came from the ray-splat intersection (else from the 2D distance)
}

// One reciprocal instead of two divisions (and the backward's three more): lavapipe's divisions are slow.
// Tried: exp(-sigma) as a cubic polynomial of 2^frac with the exponent added to the bits: slower, since
// the driver's own exp is already a short polynomial.
fn alpha_from(s: ProjectedSurfel, p: vec3<f32>, d: vec2<f32>) -> AlphaEval {
    var a: AlphaEval;
    a.d = d;
    let sigma_2d = dot(d, d);
    a.inv_pz = 1.0 / p.z;
    a.uv = p.xy * a.inv_pz;
    let sigma_3d = 0.5 * dot(a.uv, a.uv);
    a.use_3d = p.z != 0.0 && sigma_3d <= sigma_2d;   // min(sigma_2d, sigma_3d), NaN-safe
    a.e = exp(-select(sigma_2d, sigma_3d, a.use_3d));
    a.raw = s.dp_dy.w * a.e;   // opacity
    return a;
}

// Alpha of surfel s at pixel centre px (the plain path: one pixel per thread).
fn surfel_alpha(s: ProjectedSurfel, px: vec2<f32>) -> f32 {
    let d = reference_offset(s, px);
    return min(MAX_ALPHA, alpha_from(s, ray_plane_at(s, d), d).raw);
}

#if !USE_SUBGROUPS
// Composite surfel `s` (with colours `col`) into the pixel state; false once the pixel is saturated.
fn blend(s: ProjectedSurfel, px: vec2<f32>, slot: u32, index: u32, result: ptr<function, PixelResult>,
         T: ptr<function, f32>) -> bool {
    let alpha = surfel_alpha(s, px);
    if alpha < ALPHA_THRESHOLD {
        return true;
    }
    let next_T = *T * (1.0 - alpha);
    if next_T <= TRANSMITTANCE_EPS {
        return false;
    }
    let w = alpha * *T;
    for (var c = 0u; c < CHUNKS; c++) {
        (*result).color[c] += w * batch_color[slot * CHUNKS + c];
    }
    (*result).normal += w * s.normal_depth.xyz;
    (*result).depth += w * s.normal_depth.w;
    *T = next_T;
    (*result).last = index;
    return true;
}
#endif

// Bit of the 4x2 pixel block holding tile-local pixel `p` (4 block columns, 8 block rows).
fn block_bit(p: vec2<u32>) -> u32 {
    return 1u << ((p.y >> 1u) * 4u + (p.x >> 2u));
}


// Pixel of thread `lid` in its tile. Consecutive threads (a subgroup) cover 4x2 blocks rather than
// rows, so that small surfels miss whole subgroups more often.
fn tile_pixel(lid: u32) -> vec2<u32> {
    return vec2<u32>((lid & 3u) | ((lid >> 1u) & 12u), ((lid >> 2u) & 1u) | ((lid >> 4u) & 14u));
}

#if !USE_SUBGROUPS
// Copy surfel `sid` into batch slot `slot` (colours padded to vec4 chunks). The subgroup variant stages
// nothing (see composite_quad).
fn stage_surfel(slot: u32, sid: u32) {
    batch_surf[slot] = projected[sid];
    for (var c = 0u; c < CHUNKS; c++) {
        var v = vec4<f32>(0.0);
        for (var e = 0u; e < 4u; e++) {
            if 4u * c + e < CHANNELS {
                v[e] = colors[sid * CHANNELS + 4u * c + e];
            }
        }
        batch_color[slot * CHUNKS + c] = v;
    }
}

// The plain variant (GPUs): one pixel per thread, 256 threads per tile.
fn composite_pixel(tile: u32, px: vec2<f32>, inside: bool, lid: u32) -> PixelResult {
    var result: PixelResult;
    var T = 1.0;
    var done = !inside;
    if lid == 0u {
        atomicStore(&done_count, 0u);
    }
    workgroupBarrier();
    if done {
        atomicAdd(&done_count, 1u);
    }
    let range = ranges[tile];
    let num_batches = ceil_div(range.y - range.x, BATCH);
    for (var b = 0u; b < num_batches; b++) {
        // Uniform exit: also the barrier that protects the batch buffers from being overwritten early.
        if workgroupUniformLoad(&done_count) >= TILE_SIZE * TILE_SIZE {
            break;
        }
        let base = range.x + b * BATCH;
        if lid < BATCH && base + lid < range.y {
            stage_surfel(lid, isect_ids[base + lid] & SURFEL_ID_MASK);
        }
        workgroupBarrier();
        let was_done = done;
        let m = min(BATCH, range.y - base);
        if !done {
            for (var j = 0u; j < m; j++) {
                if !blend(batch_surf[j], px, j, base + j + 1u - range.x, &result, &T) {
                    done = true;
                    break;
                }
            }
        }
        if done && !was_done {
            atomicAdd(&done_count, 1u);
        }
    }
    result.transmittance = T;
    return result;
}
#else
// The subgroup variant (CPU drivers such as lavapipe) of composite_pixel, for at most 4 channels.
// Lavapipe runs a subgroup as one SIMD register, turns every workgroup-memory read with a loop-varying
// index into one scalar load per lane and every branch into masked work. So each lane reads one surfel,
// the subgroup passes them around with shuffles, and the blend is written branch-free with selects
// (same arithmetic as blend() above). Colours stay in one vec4 register: the driver mishandles
// shuffles of private-array elements.
//
// Each subgroup walks the tile's list on its own, with no barriers: it lists, BATCH intersections at a
// time, those whose block bits (block_bits.wgsl, packed into the ids by emission) meet its pixels, and a lane
// reads the surfel it passes around (and its colour) from storage, so only surfels that touch the
// subgroup's block are read, and none is copied through workgroup memory, whose stores lavapipe runs one
// lane at a time; this is faster on lavapipe than staging the surfels and colours as the plain variant
// does, on fitted avatars and the standard scene alike. Lavapipe turns a shader with barriers into a
// coroutine and keeps every variable a loop carries in the coroutine's frame, writing each through the
// lane mask (a load, a blend and a store), so this variant has no barriers at all (staging the batches'
// block masks between barriers was slower); images and gradients are bit-identical either way.
//
// Each thread composites four pixels of one column, ROW_STEP apart, so that a subgroup of 8 covers a
// 4x8 block (see tile_pixel_quad) and every surfel passed around serves four times as many pixels
// (fewer pixels per thread pass each surfel around more often). A surfel whose footprint (block mask)
// misses the subgroup's block is skipped by the whole subgroup at once: the intersections that can touch
// it first go, in order, into its row of hit_entries, and only then is surfel data read, SG hits at a
// time. (Lavapipe runs every branch body, masked, and every loop body at least once, so reading SG
// staged surfels per step, hit or not, would pay the reads and one blend for several times as many
// steps.) Tried against the shuffles and slower: reading each hit from workgroup memory at its
// (subgroup-uniform) slot; the k loop unrolled into SG steps with subgroupBroadcast at constant lanes
// (WGSL wants a const lane). No faster: recording the hit's number instead of shuffling its slot for
// `last`, or shuffling only the colour's xyz for 3 channels.
const RASTER_THREADS: u32 = 64u;                  // per tile: four pixels each
const ROW_STEP: vec2<u32> = vec2<u32>(0u, 2u);   // from one of a thread's pixels to the next

// First pixel of thread `lid` in its tile: 4x8 blocks (4 across, 2 down), 8 consecutive threads
// taking a block's rows 0-1 and, through their other pixels, rows 2-7.
fn tile_pixel_quad(lid: u32) -> vec2<u32> {
    return vec2<u32>(((lid >> 1u) & 12u) | (lid & 3u), ((lid >> 2u) & 8u) | ((lid >> 2u) & 1u));
}

// First pixel (global) of lane `sg_lane` in 4x8 block `g` of the tile at `origin` (block g = bit g of
// tile_block_bits: column g & 3, band g >> 2): that of thread 8 g + sg_lane, subgroup g's lane sg_lane.
fn block_first_pixel(origin: vec2<u32>, g: u32, sg_lane: u32) -> vec2<u32> {
    return origin + tile_pixel_quad(8u * g + sg_lane);
}

// Blocks of the tile (see block_bit) that the pixels of a thread whose first pixel is `p` lie in.
fn quad_blocks(p: vec2<u32>) -> u32 {
    return block_bit(p) | block_bit(p + ROW_STEP) | block_bit(p + 2u * ROW_STEP) | block_bit(p + 3u * ROW_STEP);
}

// One pixel's compositing state: the result so far and, in `state`, what the inner loop updates per hit
// (this batch's sums, added to the result at the batch's end). A finished pixel (saturated, or outside
// the image) keeps its transmittance negated, so that T's sign is the done flag (is_done) and the state
// needs no separate boolean register.
struct BlendState {
    T: f32,
    acc_color: vec4<f32>,   // with DEPTH_IN_COLOR the depth sum in w
    acc_normal: vec3<f32>,
    acc_depth: f32,         // unused with DEPTH_IN_COLOR
    last: u32,
}

struct PixelBlend {
    px: vec2<f32>,
    state: BlendState,
    result: PixelResult,
}

// With fewer than four channels projection puts the depth in the colour's padding lane (colors4.w), so
// that a pixel's depth sum rides in its colour sum: one register and one multiply-add fewer per pixel
// and surfel in the inner loop, which spills, and one shuffle fewer per surfel (images bit-identical).
// The backward's replay multiplies that lane by a zero upstream gradient.
const DEPTH_IN_COLOR: bool = CHANNELS < 4u;

fn start_blend(pix: vec2<u32>) -> PixelBlend {
    var b: PixelBlend;
    b.px = vec2<f32>(pix) + 0.5;
    b.state.T = select(-1.0, 1.0, pix.x < params.image_size.x && pix.y < params.image_size.y);
    b.result.transmittance = 1.0;
    return b;
}

// The terms of a surfel's alpha that a thread's four pixels share, at its first pixel `px`: p and the
// offset d there. The pixels lie in one column, so p at the pixel dy rows down is p + dy dp_dy, which
// spares two cross products per pixel (most in the backward); p comes from its linear form rather than
// (px.x T2 - T0) x (px.y T2 - T1) per surfel and thread: see ray_plane.wgsl and docs/design.md.
struct ColumnAlpha {
    p: vec3<f32>,      // at the first pixel
    d: vec2<f32>,      // at the first pixel
}

fn column_alpha(s: ProjectedSurfel, px: vec2<f32>) -> ColumnAlpha {
    let d = reference_offset(s, px);
    return ColumnAlpha(ray_plane_at(s, d), d);
}

// Alpha terms of the thread's pixel `k` (0-3: k ROW_STEPs below the first), forward and backward alike.
// Pixel k's p and d are pixel k - 1's plus one row step, additions shared by the four calls, rather
// than a multiply-add each.
fn quad_alpha(s: ProjectedSurfel, c: ColumnAlpha, k: u32) -> AlphaEval {
    if k == 0u {   // constant after inlining: the first pixel takes the column's own p and d
        return alpha_from(s, c.p, c.d);
    }
    let step = f32(ROW_STEP.y);
    let dp = step * s.dp_dy.xyz;   // exact (a power of two): the same for every k, so computed once
    var p = c.p + dp;
    var d = c.d + vec2<f32>(0.0, step);
    if k >= 2u {   // constant after inlining; p and d of pixel k - 1 are common subexpressions
        p += dp;
        d.y += step;
    }
    if k >= 3u {
        p += dp;
        d.y += step;
    }
    return alpha_from(s, p, d);
}

fn is_done(b: PixelBlend) -> bool {
    return b.state.T < 0.0;
}

fn blend_select(alpha: f32, normal: vec3<f32>, depth: f32, col: vec4<f32>, index: u32, b: ptr<function, BlendState>) {
    let T = (*b).T;
    let next_T = T * (1.0 - alpha);
    let contrib = alpha >= ALPHA_THRESHOLD && T > 0.0;
    let saturate = contrib && next_T <= TRANSMITTANCE_EPS;
    let use_it = contrib && !saturate;
    let w = select(0.0, alpha * T, use_it);
    (*b).acc_color += w * col;
    (*b).acc_normal += w * normal;
    if !DEPTH_IN_COLOR {   // constant
        (*b).acc_depth += w * depth;
    }
    (*b).T = select(select(T, -T, saturate), next_T, use_it);
    (*b).last = select((*b).last, index, use_it);
}

fn end_batch(b: ptr<function, PixelBlend>) {
    let st = (*b).state;
    (*b).result.color[0] += st.acc_color;
    (*b).result.normal += st.acc_normal;
    (*b).result.depth += select(st.acc_depth, st.acc_color.w, DEPTH_IN_COLOR);
    (*b).result.last = max((*b).result.last, st.last);
    (*b).state.acc_color = vec4<f32>(0.0);
    (*b).state.acc_normal = vec3<f32>(0.0);
    (*b).state.acc_depth = 0.0;
    (*b).state.last = 0u;
    (*b).result.transmittance = abs(st.T);
}

// What the forward blends of hit k of the subgroup's current group of SG (lane k holds it: `mine`, its
// colour `mine_col`), passed to every lane.
struct ShuffledHit {
    s: ProjectedSurfel,   // normal_depth left zero: see normal and depth
    normal: vec3<f32>,
    depth: f32,           // 0 with DEPTH_IN_COLOR (the depth rides in col.w)
    col: vec4<f32>,
}

fn shuffle_hit(mine: ProjectedSurfel, mine_col: vec4<f32>, k: u32) -> ShuffledHit {
    var h: ShuffledHit;
    h.s = ProjectedSurfel(subgroupShuffle(mine.p_ref, k), subgroupShuffle(mine.dp_dx, k),
                          subgroupShuffle(mine.dp_dy, k), vec4<f32>(0.0));
    h.normal = subgroupShuffle(mine.normal_depth.xyz, k);
    h.depth = 0.0;
    if !DEPTH_IN_COLOR {   // constant
        h.depth = subgroupShuffle(mine.normal_depth.w, k);
    }
    h.col = subgroupShuffle(mine_col, k);
    return h;
}

// Blend `h` (local index + 1 `index`) into the state `st` of a thread's pixel k (quad_alpha; `ca` its
// column's terms), alpha capped at `cap`. Both subgroup forwards (composite_quad, tile_walk_fwd.wgsl)
// blend through it.
fn blend_pixel(h: ShuffledHit, ca: ColumnAlpha, k: u32, index: u32, cap: f32, st: ptr<function, BlendState>) {
    blend_select(min(cap, quad_alpha(h.s, ca, k).raw), h.normal, h.depth, h.col, index, st);
}

// blend_pixel for the four pixels of a thread whose first pixel is at `px`.
fn blend_quad(h: ShuffledHit, index: u32, px: vec2<f32>, cap: f32, a: ptr<function, BlendState>,
              b: ptr<function, BlendState>, c: ptr<function, BlendState>, d: ptr<function, BlendState>) {
    let ca = column_alpha(h.s, px);
    blend_pixel(h, ca, 0u, index, cap, a);
    blend_pixel(h, ca, 1u, index, cap, b);
    blend_pixel(h, ca, 2u, index, cap, c);
    blend_pixel(h, ca, 3u, index, cap, d);
}

// Blend hit k of the subgroup's current group of SG (lane k holds it) into the four pixels' states;
// `valid` false (a step's second hit past the group's end) caps alpha at 0, below ALPHA_THRESHOLD, which
// changes nothing (lane k still holds a real surfel, so nothing reads past the group).
fn blend_hit(k: u32, valid: bool, mine: ProjectedSurfel, mine_col: vec4<f32>, mine_slot: u32, index_base: u32,
             px: vec2<f32>, a: ptr<function, BlendState>, b: ptr<function, BlendState>,
             c: ptr<function, BlendState>, d: ptr<function, BlendState>) {
    blend_quad(shuffle_hit(mine, mine_col, k), index_base + subgroupShuffle(mine_slot, k), px,
               select(0.0, MAX_ALPHA, valid), a, b, c, d);
}

// composite_pixel for the four pixels of thread `lid` (first pixel `pix`, global), into *a .. *d.
fn composite_quad(tile: u32, pix: vec2<u32>, sg_lane: u32, sg_id: u32,
                  a: ptr<function, PixelBlend>, b: ptr<function, PixelBlend>,
                  c: ptr<function, PixelBlend>, d: ptr<function, PixelBlend>) {
    *a = start_blend(pix);
    *b = start_blend(pix + ROW_STEP);
    *c = start_blend(pix + 2u * ROW_STEP);
    *d = start_blend(pix + 3u * ROW_STEP);
    let range = ranges[tile];
    let tile_px = pix % TILE_SIZE;
    let my_blocks = lanes_or(quad_blocks(tile_px));
    let row = sg_id * (BATCH + SG);
    // Each subgroup walks the tile's list on its own, BATCH intersections at a time, and stops once its
    // pixels are saturated: no barriers. (Lavapipe turns a shader with barriers into a coroutine and keeps
    // every variable a loop carries in the coroutine's frame, written through the lane mask; see the
    // two-hit steps below.)
    for (var base = range.x; base < range.y; base += BATCH) {
        if all_lanes(is_done(*a) && is_done(*b) && is_done(*c) && is_done(*d)) {
            break;
        }
        let m = min(BATCH, range.y - base);
        let num_hits = list_hits(base, m, my_blocks, row, sg_lane);
        for (var h = 0u; h < num_hits; h += SG) {
            if all_lanes(is_done(*a) && is_done(*b) && is_done(*c) && is_done(*d)) {
                break;
            }
            let mine_hit = hit_entries[row + min(h + sg_lane, num_hits - 1u)];
            let mine_slot = hit_slot(mine_hit);
            let mine_sid = hit_surfel(mine_hit);
            let mine = projected[mine_sid];
            let mine_col = colors4[mine_sid];
            let n = min(SG, num_hits - h);
            // Front to back, two hits per step: lavapipe writes a variable that a loop carries through the
            // loop's lane mask, 9 values per pixel, and copies made in the step are plain values, so
            // the pixels' states take those writes once per two hits. One hit per step is slower; four
            // spill registers. Images are bit-identical. (The backward's replay, whose flush follows
            // every hit, stays at one per step: two were slower there.)
            for (var k = 0u; k < n; k += 2u) {
                var sa = (*a).state;
                var sb = (*b).state;
                var sc = (*c).state;
                var sd = (*d).state;
                blend_hit(k, true, mine, mine_col, mine_slot, base + 1u - range.x, (*a).px, &sa, &sb, &sc, &sd);
                blend_hit(k + 1u, k + 1u < n, mine, mine_col, mine_slot, base + 1u - range.x, (*a).px, &sa, &sb, &sc, &sd);
                (*a).state = sa;
                (*b).state = sb;
                (*c).state = sc;
                (*d).state = sd;
            }
        }
        end_batch(a);
        end_batch(b);
        end_batch(c);
        end_batch(d);
    }
}
#endif
