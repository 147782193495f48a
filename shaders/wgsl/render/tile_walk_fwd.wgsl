// The forward rasterizers' entry point for 8-lane CPU drivers (TILE_WALK: lavapipe): one subgroup
// composites the whole 16x16 tile. Included by rasterize_entry.wgsl; composite_quad's per-pixel
// arithmetic (blend_pixel), its batches and so its images, bit for bit.
//
// The per-subgroup variant (composite_quad) gives each of a tile's 8 subgroups one 4x8 block: each
// subgroup lists, from the whole tile list, the intersections whose block bits meet its block, and reads
// and passes around (shuffles) the surfel of every hit. Here one subgroup walks the tile list once, reads
// each intersection's surfel once (one per lane, 8 at a time) and blends it into each of the tile's
// eight blocks its block bits reach, keeping the eight blocks' pixel states (BlockBlend: a lane's four
// pixels of the block) in its registers and stack. What the per-subgroup variant does once per block a
// surfel reaches (between two and three per intersection on the standard scene) this does once per
// intersection: the list scan, the surfel loads (lane by lane on lavapipe) and the shuffles; the bit
// tests select the blocks through branches on subgroup-uniform values (subgroupBroadcast), which
// lavapipe compiles as jumps.
//
// Within a block it also skips the lanes' pixels k (rows 2 k, 2 k + 1 of the block) that lie outside
// the rows of the surfel's pixel box (pixel_rows, written by projection; tile_quads in block_bits.wgsl),
// where its alpha is below 1/255 and blending changes nothing: about a third of the block pixels the
// walk would evaluate on the standard scene; images bit-identical.
// The backward's replay is slower with the same skips (the branches split its per-pixel
// accumulations), and exact 4x2 quads from the surfel's ellipse cost more to compute per hit than they
// save; neither is used.

#if USED_BLOCKS
// For the backward's replay (tile_walk_bwd.wgsl), per intersection of the tile list (replayed renders):
// the blocks (bit g) where some pixel took the surfel. The replay skips the others, where it would add
// only zeros.
@group(0) @binding(19) var<storage, read_write> used_blocks: array<u32>;
#endif

// The four pixels of a lane in one 4x8 block of the tile.
struct BlockBlend {
    a: PixelBlend,
    b: PixelBlend,
    c: PixelBlend,
    d: PixelBlend,
}

fn start_block_blend(origin: vec2<u32>, g: u32, sg_lane: u32) -> BlockBlend {
    let pix = block_first_pixel(origin, g, sg_lane);
    return BlockBlend(start_blend(pix), start_blend(pix + ROW_STEP), start_blend(pix + 2u * ROW_STEP),
                      start_blend(pix + 3u * ROW_STEP));
}

// Bit g when a pixel of block r took the hit numbered `index` (its last contributor is now that hit),
// where the walk records the used blocks (USED_BLOCKS); else 0, which the compiler drops.
fn block_used(r: BlockBlend, g: u32, index: u32) -> u32 {
#if USED_BLOCKS
    let used = r.a.state.last == index || r.b.state.last == index || r.c.state.last == index
            || r.d.state.last == index;
    return select(0u, 1u << g, used);
#else
    return 0u;
#endif
}

// Bit g unless every pixel of block g is saturated or outside the image (then no later surfel counts).
fn block_open(b: BlockBlend, g: u32) -> u32 {
    return select(1u << g, 0u, all_lanes(is_done(b.a) && is_done(b.b) && is_done(b.c) && is_done(b.d)));
}

// Blend `h` into the pixels of block g (*r) among its quads (nibble g of hit_quads: a lane's pixel k in
// bit k; subgroup-uniform, so the branches are jumps): those in the rows of the surfel's box
// (tile_quads). Each pixel's state is copied into a value of its branch and back, as in composite_quad's
// steps (lavapipe writes a variable that a loop carries through the loop's lane mask); copying all four
// around the branches would pay for the pixels the branches skip.
// Returns block_used for this lane.
fn blend_block(h: ShuffledHit, index: u32, hit_quads: u32, g: u32, r: ptr<function, BlockBlend>) -> u32 {
    let quads = block_quads(hit_quads, g);
    let ca = column_alpha(h.s, (*r).a.px);
    if (quads & 1u) != 0u { (*r).a.state = blended(h, ca, 0u, index, (*r).a.state); }
    if (quads & 2u) != 0u { (*r).b.state = blended(h, ca, 1u, index, (*r).b.state); }
    if (quads & 4u) != 0u { (*r).c.state = blended(h, ca, 2u, index, (*r).c.state); }
    if (quads & 8u) != 0u { (*r).d.state = blended(h, ca, 3u, index, (*r).d.state); }
    return block_used(*r, g, index);
}

// Block g's nibble of a hit's quads (bits 4 g .. 4 g + 3, see tile_quads).
fn block_quads(quads: u32, g: u32) -> u32 {
    return (quads >> (4u * g)) & 15u;
}

// Pixel k's state `st` after blending `h` into it (blend_pixel on a copy).
fn blended(h: ShuffledHit, ca: ColumnAlpha, k: u32, index: u32, st: BlendState) -> BlendState {
    var s = st;
    blend_pixel(h, ca, k, index, MAX_ALPHA, &s);
    return s;
}

fn end_block_batch(r: ptr<function, BlockBlend>) {
    var a = (*r).a;
    var b = (*r).b;
    var c = (*r).c;
    var d = (*r).d;
    end_batch(&a);
    end_batch(&b);
    end_batch(&c);
    end_batch(&d);
    *r = BlockBlend(a, b, c, d);
}

// Block g's results, through the variant's write_block_pixels (rasterize_fwd.wgsl, rasterize_texture.wgsl):
// the block's first pixel (lane 0's) and this lane's.
fn write_block(origin: vec2<u32>, g: u32, sg_lane: u32, r: BlockBlend) {
    write_block_pixels(block_first_pixel(origin, g, 0u), block_first_pixel(origin, g, sg_lane), sg_lane,
                       r.a.result, r.b.result, r.c.result, r.d.result);
}

#include "render/tile_walk_main.wgsl"

// Composite one tile with one subgroup.
fn walk(tile: u32, sg_lane: u32) {
    let origin = vec2<u32>(tile % params.tile_grid.x, tile / params.tile_grid.x) * TILE_SIZE;
    // Eight named states rather than an array: an indexed private array would live in per-lane scratch.
    var r0 = start_block_blend(origin, 0u, sg_lane);
    var r1 = start_block_blend(origin, 1u, sg_lane);
    var r2 = start_block_blend(origin, 2u, sg_lane);
    var r3 = start_block_blend(origin, 3u, sg_lane);
    var r4 = start_block_blend(origin, 4u, sg_lane);
    var r5 = start_block_blend(origin, 5u, sg_lane);
    var r6 = start_block_blend(origin, 6u, sg_lane);
    var r7 = start_block_blend(origin, 7u, sg_lane);
    let range = ranges[tile];
    var open = 255u;   // blocks with a pixel still taking surfels
    for (var base = range.x; base < range.y && open != 0u; base += BATCH) {
        let m = min(BATCH, range.y - base);
        for (var h = 0u; h < m; h += SG) {
            open = block_open(r0, 0u) | block_open(r1, 1u) | block_open(r2, 2u) | block_open(r3, 3u)
                 | block_open(r4, 4u) | block_open(r5, 5u) | block_open(r6, 6u) | block_open(r7, 7u);
            if open == 0u {
                break;
            }
            let n = min(SG, m - h);
            let mine_id = isect_ids[base + h + min(sg_lane, n - 1u)];
            let mine_sid = mine_id & SURFEL_ID_MASK;
            let mine = load_projected(mine_sid);
            let mine_col = load_color4(mine_sid);
            let mine_quads = tile_quads(pixel_rows[mine_sid], origin.y, mine_id >> SURFEL_ID_BITS);
            let open_quads = block_nibbles(open);
#if USED_BLOCKS
            // This lane's used blocks of the group's hits, hit k's at bits 8 (k % 4) of word k / 4: the OR
            // over the lanes then takes two reductions per group instead of one per hit.
            var used_lo = 0u;
            var used_hi = 0u;
#endif
            for (var k = 0u; k < n; k++) {
                // Lane 0's copy of the shuffled quads: uniform, so the branches below are jumps.
                let quads = subgroupBroadcast(subgroupShuffle(mine_quads, k), 0u) & open_quads;
                if quads != 0u {
                    let hit = shuffle_hit(mine, mine_col, k);
                    let index = base + h + k + 1u - range.x;   // one past its local index (`last`)
                    var used = 0u;   // block_used of the blocks it reaches
                    if block_quads(quads, 0u) != 0u { used |= blend_block(hit, index, quads, 0u, &r0); }
                    if block_quads(quads, 1u) != 0u { used |= blend_block(hit, index, quads, 1u, &r1); }
                    if block_quads(quads, 2u) != 0u { used |= blend_block(hit, index, quads, 2u, &r2); }
                    if block_quads(quads, 3u) != 0u { used |= blend_block(hit, index, quads, 3u, &r3); }
                    if block_quads(quads, 4u) != 0u { used |= blend_block(hit, index, quads, 4u, &r4); }
                    if block_quads(quads, 5u) != 0u { used |= blend_block(hit, index, quads, 5u, &r5); }
                    if block_quads(quads, 6u) != 0u { used |= blend_block(hit, index, quads, 6u, &r6); }
                    if block_quads(quads, 7u) != 0u { used |= blend_block(hit, index, quads, 7u, &r7); }
#if USED_BLOCKS
                    if k < 4u {
                        used_lo |= used << (8u * k);
                    } else {
                        used_hi |= used << (8u * (k - 4u));
                    }
#endif
                }
            }
#if USED_BLOCKS
            let word = select(lanes_or(used_lo), lanes_or(used_hi), sg_lane >= 4u);   // lane l: hit l's
            if sg_lane < n {
                used_blocks[base + h + sg_lane] = (word >> (8u * (sg_lane & 3u))) & 255u;
            }
#endif
        }
        end_block_batch(&r0);
        end_block_batch(&r1);
        end_block_batch(&r2);
        end_block_batch(&r3);
        end_block_batch(&r4);
        end_block_batch(&r5);
        end_block_batch(&r6);
        end_block_batch(&r7);
    }
    write_block(origin, 0u, sg_lane, r0);
    write_block(origin, 1u, sg_lane, r1);
    write_block(origin, 2u, sg_lane, r2);
    write_block(origin, 3u, sg_lane, r3);
    write_block(origin, 4u, sg_lane, r4);
    write_block(origin, 5u, sg_lane, r5);
    write_block(origin, 6u, sg_lane, r6);
    write_block(origin, 7u, sg_lane, r7);
}
