// Gradient accumulation into the per-surfel gradient buffers, with native float atomics where the
// adapter offers them (define FLOAT_ATOMICS) and a compare-and-swap loop on the bit pattern otherwise.
// Bindings 12 (projection gradients, 16 floats per surfel) and 13 (colour gradients, CHANNELS each).
// Not declared with GRAD_RECORDS (rasterize_bwd.wgsl), which writes per-intersection records instead.

#if !GRAD_RECORDS
#if FLOAT_ATOMICS
@group(0) @binding(12) var<storage, read_write> v_proj: array<atomic<f32>>;     // [N, 16]
@group(0) @binding(13) var<storage, read_write> v_colors: array<atomic<f32>>;   // [N, CHANNELS]

fn add_proj(i: u32, v: f32) {
    atomicAdd(&v_proj[i], v);
}

fn add_color(i: u32, v: f32) {
    atomicAdd(&v_colors[i], v);
}
#else
@group(0) @binding(12) var<storage, read_write> v_proj: array<atomic<u32>>;     // [N, 16] f32 bits
@group(0) @binding(13) var<storage, read_write> v_colors: array<atomic<u32>>;   // [N, CHANNELS] f32 bits

fn add_proj(i: u32, v: f32) {
    var old = atomicLoad(&v_proj[i]);
    loop {
        let r = atomicCompareExchangeWeak(&v_proj[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}

fn add_color(i: u32, v: f32) {
    var old = atomicLoad(&v_colors[i]);
    loop {
        let r = atomicCompareExchangeWeak(&v_colors[i], old, bitcast<u32>(bitcast<f32>(old) + v));
        if r.exchanged {
            break;
        }
        old = r.old_value;
    }
}
#endif
#endif

// Layout of the 16 projection gradients of one surfel (mirrored in gma/render/layouts.py).
const G_P_REF: u32 = 0u;     // dL/dp_ref (3): the ray plane (ProjectedSurfel; project_bwd.wgsl turns
const G_DP_DX: u32 = 3u;     // dL/ddp_dx (3)   these three into dL/dT)
const G_DP_DY: u32 = 6u;     // dL/ddp_dy (3)
const G_MU2D: u32 = 9u;      // dL/dc (2), the reference point: the projected centre where it is not clamped
const G_OPACITY: u32 = 11u;  // dL/dopacity (1)
const G_NORMAL: u32 = 12u;   // dL/dnormal, camera space (3)
const G_DEPTH: u32 = 15u;    // dL/ddepth (1)
const G_STRIDE: u32 = 16u;
