// Which 4x2 pixel blocks of a tile a surfel can reach with alpha >= 1/255, for the rasterizers' subgroup
// variant (CPU drivers), from the block bands projection wrote (write_bands in project_fwd.wgsl).
// Emission (emit_isects.wgsl, define BLOCK_BITS) packs them into the top SURFEL_ID_BITS.. bits of each
// intersection's surfel id, so that a subgroup learns which listed intersections reach its pixels from
// the ids it reads anyway: no mask pass and no mask buffer (a pass after the tile sort that wrote each
// intersection's mask would cost more than packing them).

// The block columns [first, last] (absolute 4-pixel columns, i32) in 8-row band `band` (absolute) that a
// surfel with block bands `w` (see write_bands in project_fwd.wgsl) can reach; first > last when none.
// span_columns clips it to a tile's four columns without branches.
fn band_span(w: vec2<u32>, band: u32) -> vec2<i32> {
    let j = band - (w.x & 0x1fffu);   // wraps above the first band
    let nb = (w.x >> 13u) & 3u;
    let col0 = i32(w.x >> 15u);
    let bits = w.y >> (10u * min(j, 2u));
    let first = select(col0 + i32(bits & 31u), col0, nb == 0u);
    let last = select(col0 + i32((bits >> 5u) & 31u), i32(w.y), nb == 0u);
    return select(vec2<i32>(1, 0), vec2<i32>(first, last), nb == 0u || j < nb);
}

// Bits 0-3: which of the four block columns from `tcol` (a tile's first) lie in `span` (band_span).
// Each clamped shift leaves out the columns before the span's first / after its last, so an empty span
// (first > last) gives none.
fn span_columns(span: vec2<i32>, tcol: u32) -> u32 {
    let t = i32(tcol);
    return (15u << u32(clamp(span.x - t, 0, 4))) & (15u >> u32(clamp(t + 3 - span.y, 0, 4)));
}

// The block columns (4 bits each) of tile `tile`'s two 8-row bands (a subgroup's height, so a finer mask
// would list no fewer hits) where a surfel with block bands `w` can reach alpha >= 1/255 at some pixel
// centre: band 0's in bits 0-3, band 1's in bits 4-7. Each holds over its band's four block rows
// (expand_block_bits). Strictly conservative (see block_shape in project_fwd.wgsl), so a subgroup that the surfel's box reaches but
// this mask does not sees only alpha < 1/255 from it, which the blend skips anyway: images and
// gradients are bit-identical to the box's. On a scene of randomly oriented surfels the bands leave a
// sixth fewer hit candidates than the box, for a little more work in projection; on small surfels
// (avatars) they change nothing either way. Tried: computing the ellipse's columns while staging, and
// per-band words read from 64 or 16 bytes per surfel: faster on the random scene, slower on avatars,
// where the extra bytes per staged surfel miss the cache.
fn tile_block_bits(w: vec2<u32>, tile_x: u32, tile_y: u32) -> u32 {
    let band = tile_y * (TILE_SIZE / 8u);
    let tcol = tile_x * (TILE_SIZE / 4u);
    return span_columns(band_span(w, band), tcol) | (span_columns(band_span(w, band + 1u), tcol) << 4u);
}

// The blocks (bit by * 4 + bx, block_bit in rasterize_core.wgsl) of tile_block_bits' 8 bits.
fn expand_block_bits(b: u32) -> u32 {
    return ((b & 15u) | ((b & 0xf0u) << 12u)) * 0x1111u;
}

// The forward tile walk's quads (tile_walk_fwd.wgsl): the tile's 4x2-pixel quads, bit 16 band + 4 column + k for
// the quad in rows 2 k, 2 k + 1 of its 8-row band `band` and 4-pixel column `column`, so that block g
// (bit g of tile_block_bits, g = 4 band + column) owns bits 4 g .. 4 g + 3 and a walking lane's pixel k
// of the block bit 4 g + k. Those of the blocks in `blocks` (tile_block_bits) whose rows lie within the
// surfel's box rows `rows` (first | last << 16, pixel_rows in project_fwd.wgsl) in the tile whose top
// row is `top`: in the others the surfel has alpha < 1/255 at every pixel.
fn tile_quads(rows: u32, top: u32, blocks: u32) -> u32 {
    let first = (clamp(rows & 0xffffu, top, top + 15u) - top) >> 1u;   // row pairs of the tile, 0-7
    let last = (clamp(rows >> 16u, top, top + 15u) - top) >> 1u;
    let pairs = ((2u << last) - 1u) & ~((1u << first) - 1u);
    // Band 0's pairs (bits 0-3) into each of its four blocks' nibbles, band 1's (bits 4-7) likewise: the
    // spread that expand_block_bits makes of a band's four columns.
    return expand_block_bits(pairs) & block_nibbles(blocks);
}

// Block bits (bit g: block g) to their quads' nibbles (bits 4 g .. 4 g + 3, see tile_quads).
fn block_nibbles(blocks: u32) -> u32 {
    var x = blocks & 0xffu;
    x = (x | (x << 12u)) & 0x000f000fu;
    x = (x | (x << 6u)) & 0x03030303u;
    x = (x | (x << 3u)) & 0x11111111u;
    return x * 15u;
}
