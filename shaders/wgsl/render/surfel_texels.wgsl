// The tile walks' reads of a surfel's projection and colour (included by rasterize_core.wgsl with
// TILE_WALK). With SURFEL_TEXELS they come from storage textures that the rasterizer filled from the
// buffers right before the pass (gma/render/surfel_texels.py, which explains why: on lavapipe a texel
// fetch serves all lanes at once, a buffer read at a lane-varying index loops over the lanes); without,
// from the buffers. Layout: surfel i's t0, t1, t2, normal_depth at texels 4 (i % 1024) + 0..3 of row
// i / 1024, its colour at texel i % 4096 of row i / 4096 (TEXEL_ROW = 4096 there).

#if SURFEL_TEXELS
@group(0) @binding(20) var projected_texels: texture_storage_2d<rgba32float, read>;
@group(0) @binding(21) var color_texels: texture_storage_2d<rgba32float, read>;

// Row k of surfel sid's projection (0: t0, 1: t1, 2: t2, 3: normal_depth).
fn load_projected_row(sid: u32, k: u32) -> vec4<f32> {
    return textureLoad(projected_texels, vec2<u32>(((sid & 1023u) << 2u) | k, sid >> 10u));
}

fn load_color4(sid: u32) -> vec4<f32> {
    return textureLoad(color_texels, vec2<u32>(sid & 4095u, sid >> 12u));
}
#else
fn load_projected_row(sid: u32, k: u32) -> vec4<f32> {
    switch k {   // k is a constant at every call: the switch folds away
        case 0u: { return projected[sid].t0; }
        case 1u: { return projected[sid].t1; }
        case 2u: { return projected[sid].t2; }
        default: { return projected[sid].normal_depth; }
    }
}

fn load_color4(sid: u32) -> vec4<f32> {
    return colors4[sid];
}
#endif

fn load_projected(sid: u32) -> ProjectedSurfel {
    return ProjectedSurfel(load_projected_row(sid, 0u), load_projected_row(sid, 1u), load_projected_row(sid, 2u),
                           load_projected_row(sid, 3u));
}
