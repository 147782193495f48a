// The ray-splat intersection in the form the rasterizers evaluate (ProjectedSurfel in
// common/render_types.wgsl): p(x) = p(c) + (x - c.x) dp_dx + (y - c.y) dp_dy, where
// p(x) = (x T2 - T0) x (y T2 - T1) for the ray transform's rows T0, T1, T2. Projection writes it
// (project_fwd.wgsl), the rasterizers evaluate it (ray_plane_at, through rasterize_core.wgsl), and
// projection backward turns their gradients with respect to it into gradients with respect to T
// (project_bwd.wgsl); both projections compute the reference point c the same way.
//
// Why a reference point: p(c) is formed from the rows shifted to c (T0 - c.x T2, T1 - c.y T2), whose
// sizes are the surfel's own, and the pixel offsets x - c stay small near the surfel, so that rounding
// stays relative to the surfel rather than to its position in the image (the plain form
// T0 x T1 + x (T1 x T2) + y (T2 x T0) would cancel products of hundreds of pixels against a result of a
// few). As (x - c) dp_dx + p(c) is p(x) for every c, any c gives the same p up to rounding: it is the
// projected centre, clamped to the image grown by RAY_PLANE_MARGIN pixels, where the centre of a
// surfel seen almost edge-on runs off to infinity.
//
// The rasterizers also take c as the centre of the 2D-distance floor (sigma = min(sigma_3d, |x - c|^2)).
// Where the clamp moves c, every pixel centre lies more than RAY_PLANE_MARGIN + 0.5 pixels from both c
// and the true centre, so the floor's sigma exceeds 20 in both, far past ln(255) = 5.54 where alpha
// drops below 1/255: each pixel takes the same sigma_3d, or nothing either way. Images and gradients
// are the renderer contract's; the centre's gradient is zero there (nothing reaches it).
//
// This is cheaper in both rasterizers than forming p = (x T2 - T0) x (y T2 - T1) per block.

const RAY_PLANE_MARGIN: f32 = 4.0;

fn ray_plane_reference(mu2d: vec2<f32>, image_size: vec2<u32>) -> vec2<f32> {
    return clamp(mu2d, vec2<f32>(-RAY_PLANE_MARGIN), vec2<f32>(image_size) + RAY_PLANE_MARGIN);
}

struct RayPlane {
    p_ref: vec3<f32>,   // p(c)
    dp_dx: vec3<f32>,   // T1 x T2
    dp_dy: vec3<f32>,   // T2 x T0
}

fn ray_plane(t0: vec3<f32>, t1: vec3<f32>, t2: vec3<f32>, c: vec2<f32>) -> RayPlane {
    // (x T2 - T0) x (y T2 - T1) with the rows shifted to c: T2 x T1' = -(T1' x T2), T0' x T2 = -(T2 x T0').
    let t0c = t0 - c.x * t2;
    let t1c = t1 - c.y * t2;
    return RayPlane(cross(t0c, t1c), cross(t1c, t2), cross(t2, t0c));
}

// The offset of pixel centre px from surfel s's reference point c (the rasterizers): the 2D distance of
// the alpha floor, and the step from p(c) to p(px).
fn reference_offset(s: ProjectedSurfel, px: vec2<f32>) -> vec2<f32> {
    return px - vec2<f32>(s.p_ref.w, s.dp_dx.w);
}

// The ray-splat intersection p at the pixel `d` away from surfel s's reference point.
fn ray_plane_at(s: ProjectedSurfel, d: vec2<f32>) -> vec3<f32> {
    return s.p_ref.xyz + d.x * s.dp_dx.xyz + d.y * s.dp_dy.xyz;
}

// d loss / dT rows from d loss / d(p(c), dp_dx, dp_dy) (`g`), c held fixed: p(x) does not depend on c,
// whose gradient comes from the 2D-distance floor alone.
struct RowGrads {
    t0: vec3<f32>,
    t1: vec3<f32>,
    t2: vec3<f32>,
}

fn ray_plane_backward(t0: vec3<f32>, t1: vec3<f32>, t2: vec3<f32>, c: vec2<f32>, g: RayPlane) -> RowGrads {
    let t0c = t0 - c.x * t2;
    let t1c = t1 - c.y * t2;
    // d(a x b) . g: d/da = b x g, d/db = g x a.
    let v_t0c = cross(t1c, g.p_ref) + cross(g.dp_dy, t2);
    let v_t1c = cross(g.p_ref, t0c) + cross(t2, g.dp_dx);
    let v_t2 = cross(g.dp_dx, t1c) + cross(t0c, g.dp_dy) - c.x * v_t0c - c.y * v_t1c;
    return RowGrads(v_t0c, v_t1c, v_t2);
}
