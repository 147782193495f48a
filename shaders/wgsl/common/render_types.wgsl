// Structs and constants shared by the render passes. The Python side mirrors these layouts in
// gma/render/layouts.py; tests/test_render_layouts.py checks that both agree.

const TILE_SIZE: u32 = 16u;
const ALPHA_THRESHOLD: f32 = 0.003921569;   // 1/255: contributions below are skipped
const MAX_ALPHA: f32 = 0.999;
const TRANSMITTANCE_EPS: f32 = 1e-4;          // compositing stops before T would reach this
const NEAR_PLANE: f32 = 0.01;
const CULLED_KEY: u32 = 0xffffffffu;
// Intersection keys of a render whose backward pass sums gradient records (RECORD_KEYS in
// emit_isects.wgsl) carry, above the tile id, the intersection's number within its surfel's list
// (the tile sort orders at most 16 bits, so the tile grid has at most 65536 tiles there).
const RECORD_KEY_SHIFT: u32 = 16u;
const TILE_KEY_MASK: u32 = 0xffffu;
// Surfel ids fit in 24 bits (the renderer takes at most 65535 * 256 surfels). In the rasterizers'
// subgroup variant the top 8 bits of a listed id carry its block bits (tile_block_bits in
// render/block_bits.wgsl), and every reader of the tile lists masks them off.
const SURFEL_ID_BITS: u32 = 24u;
const SURFEL_ID_MASK: u32 = (1u << SURFEL_ID_BITS) - 1u;

// Vec4 t of a buffer copied into (or written as) an rgba32float texture lies at texel (t % 4096, t / 4096)
// (TEXEL_ROW in gma/render/surfel_texels.py): the lavapipe tile walks' surfel and record textures.
fn texel_at(t: u32) -> vec2<u32> {
    return vec2<u32>(t & 4095u, t >> 12u);
}

// Per-frame parameters (uniform, 128 bytes).
struct RenderParams {
    w2c_r0: vec4<f32>,          // rows of the world->camera [R | t]
    w2c_r1: vec4<f32>,
    w2c_r2: vec4<f32>,
    k_r0: vec4<f32>,            // rows of the intrinsics K (w unused)
    k_r1: vec4<f32>,
    k_r2: vec4<f32>,
    image_size: vec2<u32>,      // width, height in pixels
    tile_grid: vec2<u32>,       // tiles in x, tiles in y
    num_surfels: u32,
    isect_capacity: u32,        // size of the intersection buffers
    num_channels: u32,
    reserved: u32,
};

// One projected surfel as the rasterizer needs it (64 bytes). With the 3x3 ray transform
// T = K [R s_u t_u, R s_v t_v, mu_c] (rows T0, T1, T2), the ray through pixel x = (x, y) meets the surfel
// at p(x) = (x T2 - T0) x (y T2 - T1), whose (u, v) = p.xy / p.z (docs/design.md, renderer contract).
// The y T2 x x T2 term vanishes, so p is linear in the pixel: p(x) = p(c) + (x - c.x) dp_dx + (y - c.y) dp_dy
// with dp_dx = T1 x T2 and dp_dy = T2 x T0. Projection stores that form about a reference point c, the
// projected centre clamped to the image's surroundings (ray_plane_reference in render/ray_plane.wgsl), so that
// a rasterizer evaluates p with two multiply-adds per component instead of two cross products, and the
// backward's d loss / dp sums need no cross products per hit (project_bwd.wgsl turns them into d loss / dT
// once per surfel). The reference point is also the centre of the 2D-distance floor: see there.
struct ProjectedSurfel {
    p_ref: vec4<f32>,           // p(c), c.x
    dp_dx: vec4<f32>,           // T1 x T2, c.y
    dp_dy: vec4<f32>,           // T2 x T0, opacity
    normal_depth: vec4<f32>,    // camera-space normal facing the camera, camera-space depth; in the tile
                                // walks' buffers (WALK_LAYOUT, surfel_texels.wgsl) the colour vec4 instead
};

// Indirect-dispatch arguments followed by the element count they were derived from (16 bytes).
struct DispatchInfo {
    groups_x: u32,
    groups_y: u32,
    groups_z: u32,
    count: u32,
};
