// Projection: one thread per surfel. Culls, builds the ray transform T, the projected centre, the
// camera-facing normal and depth, the screen rectangle of tiles the surfel can touch with alpha >= 1/255,
// and the depth key for the global depth sort.
#include "common/render_types.wgsl"
#include "common/math.wgsl"
#include "render/ray_plane.wgsl"

@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> means: array<f32>;        // [N, 3]
@group(0) @binding(2) var<storage, read> quats: array<f32>;        // [N, 4] (w, x, y, z)
@group(0) @binding(3) var<storage, read> scales: array<f32>;       // [N, 2]
@group(0) @binding(4) var<storage, read> opacities: array<f32>;    // [N]
@group(0) @binding(5) var<storage, read_write> projected: array<ProjectedSurfel>;  // [N]
@group(0) @binding(6) var<storage, read_write> tile_rects: array<vec4<u32>>;      // [N] see tile_list
@group(0) @binding(7) var<storage, read_write> tile_counts: array<u32>;           // [N]
@group(0) @binding(8) var<storage, read_write> depth_keys: array<u32>;            // [N]
@group(0) @binding(9) var<storage, read_write> surfel_ids: array<u32>;            // [N]
// What the rasterizers' subgroup variant needs per intersection, precomputed here once per surfel (see
// block_bits.wgsl and composite_quad in rasterize_core.wgsl): the 4-pixel columns of each 8-row band that the surfel can reach
// (see write_bands below; tile_block_bits turns them into the tile's blocks), and the first four colour channels as one
// zero-padded vec4: one load per surfel in the rasterizers instead of a scalar load per channel and a
// loop over rows.
@group(0) @binding(10) var<storage, read_write> block_bands: array<vec2<u32>>;    // [N]
@group(0) @binding(11) var<storage, read> colors: array<f32>;                     // [N, num_channels]
@group(0) @binding(12) var<storage, read_write> colors4: array<vec4<f32>>;        // [N]
// Define WALK_LAYOUT (the tile walks', with TILE_WALK): `projected` holds each surfel's colour vec4 in place
// of its normal and depth, and colors4 those (see the writes below and surfel_texels.wgsl).
#if PIXEL_ROWS
// For the forward tile walk (tile_walk_fwd.wgsl, TILE_WALK): the first and last pixel row of the surfel's box
// (first | last << 16), from which it skips the rows of a block that the surfel cannot reach.
@group(0) @binding(14) var<storage, read_write> pixel_rows: array<u32>;           // [N]
#endif
// [4], set to (0, 0, ~0, 0) before this pass: [1] the intersections wanted (the sum of tile_counts),
// [2] the smallest and [3] the largest depth key of the surfels listed in some tile (tile count > 0);
// [0] is isect_setup.wgsl's. The host reads them to size the intersection buffers and to choose how
// many bits of key - [2] the depth sort orders (see depth_key_bits in gma/render/rasterizer.py).
@group(0) @binding(13) var<storage, read_write> stats: array<atomic<u32>>;

#if !USE_SUBGROUPS
// This workgroup's share of stats[1..3] (one global atomic each per workgroup).
var<workgroup> group_stats: array<atomic<u32>, 3>;
#endif

// What the rasterizers' subgroup variant needs to find the 4x2 pixel blocks of a tile that a surfel can
// reach with alpha >= 1/255 (see write_bands). The ellipse's points at height Y = y - centre.y span x = centre.x + k Y +- sqrt(c - q Y^2)
// for |Y| <= h_y; its rightmost point lies at Y = ystar, its leftmost at -ystar.
struct BlockShape {
    ellipse: vec4<f32>,         // centre x, centre y, k, c
    band: vec4<f32>,            // q, ystar, h_y, radius of the 2D-distance disc around the projected centre
};

fn cull(i: u32) {
    tile_counts[i] = 0u;
    depth_keys[i] = CULLED_KEY;
    surfel_ids[i] = i;
}

// Projects surfel gid.x (none past the end) and adds its depth key and tile count to stats.
#if USE_SUBGROUPS
// With subgroups (chosen by the adapter's feature, not by the rasterizer variant): subgroup reductions,
// then one lane adds the subgroup's share. On CPU drivers workgroup atomics are scalar loops over the
// lanes: three per surfel were most of projection's time on lavapipe.
#if WORK_QUEUE
@group(0) @binding(15) var<storage, read_write> work_queue: array<atomic<u32>>;
#include "common/work_queue.wgsl"

// One workgroup per driver thread (common/work_queue.wgsl): each subgroup projects chunks of QUEUE_CHUNK
// surfels until none is left, and adds its totals to stats once.
@compute @workgroup_size(256)
fn main(@builtin(subgroup_invocation_id) sg_lane: u32, @builtin(subgroup_size) sg_size: u32) {
    var count = 0u;
    var lo = CULLED_KEY;
    var hi = 0u;
    loop {
        let first = take_work(QUEUE_CHUNK, sg_lane);
        if first >= params.num_surfels {
            break;
        }
        for (var j = 0u; j < QUEUE_CHUNK; j += sg_size) {
            let q = project_if_any(first + j + sg_lane);
            count += q.y;
            lo = min(lo, select(CULLED_KEY, q.x, q.y != 0u));
            hi = max(hi, select(0u, q.x, q.y != 0u));
        }
    }
    count = subgroupAdd(count);
    lo = subgroupMin(lo);
    hi = subgroupMax(hi);
    if sg_lane == 0u {
        atomicAdd(&stats[1], count);
        atomicMin(&stats[2], lo);
        atomicMax(&stats[3], hi);
    }
}
#else
@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(subgroup_invocation_id) sg_lane: u32) {
    let r = project_if_any(gid.x);
    let count = subgroupAdd(r.y);
    let lo = subgroupMin(select(CULLED_KEY, r.x, r.y != 0u));
    let hi = subgroupMax(select(0u, r.x, r.y != 0u));
    if sg_lane == 0u {
        atomicAdd(&stats[1], count);
        atomicMin(&stats[2], lo);
        atomicMax(&stats[3], hi);
    }
}
#endif
#else
@compute @workgroup_size(256)
fn main(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    if lid < 3u {
        atomicStore(&group_stats[lid], select(0u, CULLED_KEY, lid == 1u));
    }
    workgroupBarrier();
    let r = project_if_any(gid.x);
    atomicAdd(&group_stats[0], r.y);
    atomicMin(&group_stats[1], select(CULLED_KEY, r.x, r.y != 0u));
    atomicMax(&group_stats[2], select(0u, r.x, r.y != 0u));
    workgroupBarrier();
    if lid == 0u {
        atomicAdd(&stats[1], atomicLoad(&group_stats[0]));
    } else if lid == 1u {
        atomicMin(&stats[2], atomicLoad(&group_stats[1]));
    } else if lid == 2u {
        atomicMax(&stats[3], atomicLoad(&group_stats[2]));
    }
}
#endif

// Depth key and tile count of surfel i (none, as if culled, past the end); surfels in no tile add
// neutral values to the key range.
fn project_if_any(i: u32) -> vec2<u32> {
    var r = vec2<u32>(CULLED_KEY, 0u);
    if i < params.num_surfels {
        r = project_surfel(i);
    }
    return r;
}

// Projects surfel i (writes its entries of every output buffer); returns its depth key and tile count.
fn project_surfel(i: u32) -> vec2<u32> {
    let mean = vec3<f32>(means[3u * i], means[3u * i + 1u], means[3u * i + 2u]);
    let opacity = opacities[i];
    let r0 = params.w2c_r0;
    let r1 = params.w2c_r1;
    let r2 = params.w2c_r2;
    let mu_c = vec3<f32>(dot(r0.xyz, mean) + r0.w, dot(r1.xyz, mean) + r1.w, dot(r2.xyz, mean) + r2.w);
    if mu_c.z <= NEAR_PLANE || opacity < ALPHA_THRESHOLD {
        cull(i);
        return vec2<u32>(CULLED_KEY, 0u);
    }
    let rot = quat_to_mat3(vec4<f32>(quats[4u * i], quats[4u * i + 1u], quats[4u * i + 2u], quats[4u * i + 3u]));
    let w2c = transpose(mat3x3<f32>(r0.xyz, r1.xyz, r2.xyz));
    let tu = w2c * rot[0] * scales[2u * i];
    let tv = w2c * rot[1] * scales[2u * i + 1u];
    var normal = w2c * rot[2];
    if dot(normal, mu_c) > 0.0 {
        normal = -normal;
    }
    // T = K * [tu, tv, mu_c]; column j of T is K times column j.
    let k = transpose(mat3x3<f32>(params.k_r0.xyz, params.k_r1.xyz, params.k_r2.xyz));
    let c0 = k * tu;
    let c1 = k * tv;
    let c2 = k * mu_c;
    let t0 = vec3<f32>(c0.x, c1.x, c2.x);
    let t1 = vec3<f32>(c0.y, c1.y, c2.y);
    let t2 = vec3<f32>(c0.z, c1.z, c2.z);

    // Projected centre: centre of the image conic of the unit circle (dual conic T diag(1,1,-1) T^T).
    let denom = t2.x * t2.x + t2.y * t2.y - t2.z * t2.z;
    if denom == 0.0 {
        cull(i);
        return vec2<u32>(CULLED_KEY, 0u);
    }
    let f = vec3<f32>(1.0, 1.0, -1.0) / denom;
    let mu2d = vec2<f32>(dot(f, t0 * t2), dot(f, t1 * t2));

    // Screen bounds: alpha = o exp(-sigma) >= 1/255 needs sigma <= ln(255 o). Sigma is the minimum of
    // (u^2+v^2)/2 (inside the circle of radius^2 = 2 ln(255 o) on the surfel) and |x - mu2d|^2 (inside a
    // disc of radius sqrt(ln(255 o)) pixels). The box is the union of both, plus a small safety margin.
    let level = log(255.0 * opacity);
    let r2u = 2.0 * level;
    let disc = sqrt(level) + 0.01;
    var lo = mu2d - vec2<f32>(disc);
    var hi = mu2d + vec2<f32>(disc);
    let d = vec3<f32>(r2u, r2u, -1.0);
    let denom_r = dot(d, t2 * t2);
    // The image of the circle is a bounded ellipse only when denom_r < 0 (the circle lies entirely in
    // front of the camera plane); otherwise it is a parabola or hyperbola.
    if denom_r < 0.0 {
        let fr = d / denom_r;
        let m = vec2<f32>(dot(fr, t0 * t2), dot(fr, t1 * t2));
        let half_ext = sqrt(max(m * m - vec2<f32>(dot(fr, t0 * t0), dot(fr, t1 * t1)), vec2<f32>(0.0)));
        let margin = 0.01 + 1e-4 * abs(m);
        lo = min(lo, m - half_ext - margin);
        hi = max(hi, m + half_ext + margin);
    } else {
        // The circle reaches the camera plane: its image is unbounded, so the whole image may be hit.
        lo = vec2<f32>(-1.0);
        hi = vec2<f32>(params.image_size) + 1.0;
    }
    // Pixels whose centres (p + 0.5) lie inside [lo, hi].
    let size = vec2<f32>(params.image_size);
    let p_lo = max(ceil(lo - 0.5), vec2<f32>(0.0));
    let p_hi = min(floor(hi - 0.5), size - 1.0);
    if any(p_lo > p_hi) || any(p_hi < vec2<f32>(0.0)) || any(p_lo > size - 1.0) {
        cull(i);
        return vec2<u32>(CULLED_KEY, 0u);
    }
    let px_lo = vec2<u32>(whole_u32(p_lo.x), whole_u32(p_lo.y));   // the box's pixels, as integers
    let px_hi = vec2<u32>(whole_u32(p_hi.x), whole_u32(p_hi.y));
    let tile_lo = px_lo / TILE_SIZE;
    let tile_hi = px_hi / TILE_SIZE;
    let extent = tile_hi - tile_lo + 1u;

#if PIXEL_ROWS
    pixel_rows[i] = px_lo.y | (px_hi.y << 16u);
#endif
    let bands = write_bands(i, block_shape(t0, t1, t2, mu2d, r2u, disc), mu2d, p_lo, p_hi, px_lo, px_hi);
    let tiles = tile_list(bands, tile_lo, tile_hi);
    tile_rects[i] = tiles;
    let nc = params.num_channels;
    let last = nc - 1u;
    // With fewer than 4 channels the depth rides in the padding lane (the subgroup rasterizer's
    // DEPTH_IN_COLOR, rasterize_core.wgsl).
    let color4 = vec4<f32>(colors[i * nc], select(0.0, colors[i * nc + min(1u, last)], nc > 1u),
                           select(0.0, colors[i * nc + min(2u, last)], nc > 2u),
                           select(mu_c.z, colors[i * nc + min(3u, last)], nc > 3u));
    let normal_depth = vec4<f32>(normal, mu_c.z);
#if WALK_LAYOUT
    // The tile walks' layout (surfel_texels.wgsl): the colour in the fourth vec4, beside the ray plane in
    // the surfel's 64 bytes, which the backward walk reads alone; the normal and depth in colors4.
    let fourth = color4;
    colors4[i] = normal_depth;
#else
    let fourth = normal_depth;
    colors4[i] = color4;
#endif
    let c = ray_plane_reference(mu2d, params.image_size);
    let plane = ray_plane(t0, t1, t2, c);
    projected[i] = ProjectedSurfel(vec4<f32>(plane.p_ref, c.x), vec4<f32>(plane.dp_dx, c.y),
                                   vec4<f32>(plane.dp_dy, opacity), fourth);
    let count = select(countOneBits(tiles.z), extent.x * extent.y, tiles.w != 0u);
    tile_counts[i] = count;
    let key = depth_key(mu_c.z);
    depth_keys[i] = key;
    surfel_ids[i] = i;
    return vec2<u32>(key, count);
}

// The footprint from which write_bands computes the rasterizers' block bands (see BlockShape above and
// tile_block_bits in block_bits.wgsl): the ellipse u^2 + v^2 <= r2u, its
// level slightly raised (1.001 r2u + 1e-3) against the rounding of log, exp and the threshold test. It is
// computed from T's rows shifted to the projected centre (t0 - mu.x t2, t1 - mu.y t2), so that the centred
// second moments below do not cancel against the square of an absolute position (hundreds of pixels):
// what is left is rounding relative to the ellipse's own size. Unbounded or degenerate images keep
// the whole box (an ellipse that covers everything).
fn block_shape(t0: vec3<f32>, t1: vec3<f32>, t2: vec3<f32>, mu: vec2<f32>, r2u: f32, disc: f32) -> BlockShape {
    var b: BlockShape;
    b.ellipse = vec4<f32>(mu, 0.0, 3e38);
    b.band = vec4<f32>(0.0, 0.0, 3e38, disc);
    let r2e = 1.001 * r2u + 1e-3;
    let d = vec3<f32>(r2e, r2e, -1.0);
    let s0 = t0 - mu.x * t2;
    let s1 = t1 - mu.y * t2;
    let dz = dot(d, t2 * t2);
    if dz < 0.0 {
        let f = d / dz;
        let m = vec2<f32>(dot(f, s0 * t2), dot(f, s1 * t2));
        let sxx = m.x * m.x - dot(f, s0 * s0);
        let syy = m.y * m.y - dot(f, s1 * s1);
        let sxy = m.x * m.y - dot(f, s0 * s1);
        let k = sxy / syy;
        let c = max(sxx - k * sxy, 0.0);
        let q = c / syy;
        let ystar = sxy / sqrt(sxx);
        let h_y = sqrt(syy);
        let v = vec4<f32>(m, k, c) + vec4<f32>(q, ystar, h_y, 0.0);   // finite iff all of them are
        if sxx > 0.0 && syy > 0.0 && all(abs(v) < vec4<f32>(1e30)) {
            b.ellipse = vec4<f32>(mu + m, k, c);
            b.band = vec4<f32>(q, ystar, h_y, disc);
        }
    }
    return b;
}

// The x-range (absolute, widened by `margin`) of the pixel centres in rows y0 .. y0 + 7 (centres) where
// the surfel can reach alpha >= 1/255: the ellipse's x-range over those rows united with the disc's box;
// lo > hi when empty. The ellipse's right edge, x(Y) = k Y + sqrt(c - q Y^2), is concave, so its
// maximum over the band clipped to [-h_y, h_y] lies at ystar clamped into it (the left edge likewise at
// -ystar): two square roots per band.
fn band_range(f: BlockShape, mu: vec2<f32>, y0: f32, margin: f32) -> vec2<f32> {
    let k = f.ellipse.z;
    let c = f.ellipse.w;
    let q = f.band.x;
    let lo_y = max(y0 - f.ellipse.y - margin, -f.band.z);
    let hi_y = min(y0 + 7.0 - f.ellipse.y + margin, f.band.z);
    let yr = clamp(f.band.y, lo_y, hi_y);
    let yl = clamp(-f.band.y, lo_y, hi_y);
    let in_e = lo_y <= hi_y;
    let in_d = abs(clamp(mu.y, y0, y0 + 7.0) - mu.y) <= f.band.w;
    let xr = f.ellipse.x + k * yr + sqrt(max(c - q * yr * yr, 0.0));
    let xl = f.ellipse.x + k * yl - sqrt(max(c - q * yl * yl, 0.0));
    let hi = max(select(-3e38, xr, in_e), select(-3e38, mu.x + f.band.w, in_d)) + margin;
    let lo = min(select(3e38, xl, in_e), select(3e38, mu.x - f.band.w, in_d)) - margin;
    return vec2<f32>(lo, hi);
}

// block_bands[i] (8 bytes, as many as the box they replace): x = the surfel's first 8-row band (y / 8
// of its box's top pixel, 13 bits) | the number of bands << 13 (1-3; 0 for BIG: taller, or wider than
// 32 columns) | the box's first 4-pixel column (x / 4) << 15. y = per band j (5 bits each, from bit
// 10 j) the first and last column, relative to the box's first, of the pixels whose centres band_range
// covers within the box (first 31, last 0 when empty); for BIG, the box's last column, for every band.
// Returns what it wrote.
fn write_bands(i: u32, f: BlockShape, mu: vec2<f32>, p_lo: vec2<f32>, p_hi: vec2<f32>, px_lo: vec2<u32>,
               px_hi: vec2<u32>) -> vec2<u32> {
    let first = px_lo.y / 8u;
    let nb = px_hi.y / 8u - first + 1u;
    let col0 = px_lo.x / 4u;
    let col1 = px_hi.x / 4u;
    if nb > 3u || col1 - col0 > 31u {
        let box = vec2<u32>(first | (col0 << 15u), col1);
        block_bands[i] = box;
        return box;
    }
    let margin = 0.01 + 1e-4 * max(abs(f.ellipse.x), abs(f.ellipse.y));
    var cols = 0u;
    for (var j = 0u; j < nb; j++) {
        let r = band_range(f, mu, f32(8u * (first + j)) + 0.5, margin);
        // Pixels whose centres p + 0.5 lie in [lo, hi], within the box.
        let x_lo = max(ceil(r.x - 0.5), p_lo.x);
        let x_hi = min(floor(r.y - 0.5), p_hi.x);
        // Whole numbers within the box (p_lo.x >= 0) when the range is not empty; clamped otherwise.
        let c = vec2<u32>(whole_u32(clamp(x_lo, 0.0, p_hi.x)) / 4u, whole_u32(clamp(x_hi, 0.0, p_hi.x)) / 4u) - col0;
        cols |= select(31u, c.x | (c.y << 5u), x_lo <= x_hi) << (10u * j);
    }
    let bands = vec2<u32>(first | (nb << 13u) | (col0 << 15u), cols);
    block_bands[i] = bands;
    return bands;
}

// The tiles that emit_isects.wgsl lists the surfel in: those of its box rectangle [lo, hi] (tile
// coordinates) that hold a 4x2 block its block bands reach. In the others the surfel has alpha < 1/255
// at every pixel (the bands are strictly conservative), so images and gradients do not change, save the
// rounding of sums whose batches shift. A band's columns [a, b] reach tiles a / 4 .. b / 4 of the
// band's tile row, exactly the tiles where tile_block_bits (block_bits.wgsl) is non-zero.
// Returns x0 | y0 << 16, x1 | y1 << 16, the reached tiles (bit (ty - y0) * 16 + tx - x0), and 1 when
// every tile of the rectangle is listed (surfels whose bands are their box's, see write_bands).
// Standard scene (100k surfels, random orientations): 238k -> 224k intersections.
fn tile_list(bands: vec2<u32>, lo: vec2<u32>, hi: vec2<u32>) -> vec4<u32> {
    let rect = vec2<u32>(lo.x | (lo.y << 16u), hi.x | (hi.y << 16u));
    let nb = (bands.x >> 13u) & 3u;
    if nb == 0u {
        return vec4<u32>(rect, 0u, 1u);
    }
    let first = bands.x & 0x1fffu;
    let col0 = bands.x >> 15u;
    var mask = 0u;
    for (var j = 0u; j < nb; j++) {
        let a = (bands.y >> (10u * j)) & 31u;
        let b = (bands.y >> (10u * j + 5u)) & 31u;
        let t0 = (col0 + a) / (TILE_SIZE / 4u) - lo.x;
        let t1 = (col0 + b) / (TILE_SIZE / 4u) - lo.x;
        let row = ((first + j) / (TILE_SIZE / 8u) - lo.y) * 16u;
        // At most 2 tile rows of at most 9 tiles (3 bands, 32 block columns).
        mask |= select(0u, ((2u << t1) - 1u) & ~((1u << t0) - 1u), a <= b) << row;
    }
    return vec4<u32>(rect, mask, 0u);
}

// The depth sort's key: DEPTH_KEY_BITS (24) bits, so that the sort takes 6 radix passes instead of 8.
// Positive floats order like their bit patterns; z > NEAR_PLANE here, so the distance of those bits from
// the near plane's is ordered too and spans 28 bits up to z ~ 4e7. Dropping its 4 lowest bits ties
// only depths within a relative 2^-19 of each other (6 um at 3 m), which keep surfel order (the sort is
// stable). Culled surfels (CULLED_KEY, whose low 24 bits are all ones) stay behind every other.
// The forward pass sorts only the low bits of key - min key that the frame's key range needs (stats
// above; 18 bits, 5 passes, on the standard scene, whose depths span 2.5-3.5; 16 bits, 4 passes, on the
// avatar-like one): the same order, so the same images, and fewer radix passes for the price of the
// subgroup reductions. The texture path, which reads nothing back, sorts all 24.
fn depth_key(z: f32) -> u32 {
    return min((bitcast<u32>(z) - bitcast<u32>(NEAR_PLANE)) >> 4u, (CULLED_KEY >> 8u) - 1u);
}
