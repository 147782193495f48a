// The tile walks' reads of a surfel's projection and colour (included by rasterize_core.wgsl with
// TILE_WALK). With SURFEL_TEXELS they come from storage textures that the rasterizer filled from the
// buffers (gma/render/surfel_texels.py, which explains why: on lavapipe a texel fetch serves all lanes at
// once, a buffer read at a lane-varying index loops over the lanes); without, from the buffers. Layout
// (texel_at): surfel i's t0, t1, t2, normal_depth are vec4s 4 i + 0..3, its colour vec4 i.

#if SURFEL_TEXELS
@group(0) @binding(20) var projected_texels: texture_storage_2d<rgba32float, read>;
@group(0) @binding(21) var color_texels: texture_storage_2d<rgba32float, read>;

// Row k of surfel sid's projection (0: t0, 1: t1, 2: t2, 3: normal_depth).
fn load_projected_row(sid: u32, k: u32) -> vec4<f32> {
    return textureLoad(projected_texels, texel_at(4u * sid + k));
}

fn load_color4(sid: u32) -> vec4<f32> {
    return textureLoad(color_texels, texel_at(sid));
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
