// The subgroup rasterizers' reads of a surfel's projection and colour, by layout (included by
// rasterize_core.wgsl with USE_SUBGROUPS; the tile walks read every surfel through them). With
// SURFEL_TEXELS (tile walks only) they come from storage textures that the rasterizer filled from the
// buffers (gma/render/surfel_texels.py, which explains why: on lavapipe a texel fetch serves all lanes at
// once, a buffer read at a lane-varying index loops over the lanes); without, from the buffers.
//
// Define WALK_LAYOUT (always with the tile walks: TILE_WALK): projection wrote the walks'
// layout (project_fwd.wgsl): a surfel's 64 bytes of `projected` hold its ray plane (p_ref, dp_dx, dp_dy) and its colour
// vec4 (channels 0-3, the depth in .w below 4 channels), and colors4 holds its normal and depth. The
// backward walk reads only the first: one cache line per surfel instead of two (the standard layout has
// the normal and depth beside the ray plane and the colour in colors4). Textures (texel_at): surfel i's four vec4s of `projected` are texels 4 i + 0..3
// of one, its colors4 vec4 texel i of the other.

#if SURFEL_TEXELS
@group(0) @binding(20) var projected_texels: texture_storage_2d<rgba32float, read>;
@group(0) @binding(21) var color_texels: texture_storage_2d<rgba32float, read>;   // colors4's copy

// Row k of surfel sid's projection (0-2: p_ref, dp_dx, dp_dy; 3: see the layout above).
fn load_projected_row(sid: u32, k: u32) -> vec4<f32> {
    return textureLoad(projected_texels, texel_at(4u * sid + k));
}

fn load_colors4_vec(sid: u32) -> vec4<f32> {
    return textureLoad(color_texels, texel_at(sid));
}
#else
fn load_projected_row(sid: u32, k: u32) -> vec4<f32> {
    switch k {   // k is a constant at every call: the switch folds away
        case 0u: { return projected[sid].p_ref; }
        case 1u: { return projected[sid].dp_dx; }
        case 2u: { return projected[sid].dp_dy; }
        default: { return projected[sid].normal_depth; }
    }
}

fn load_colors4_vec(sid: u32) -> vec4<f32> {
    return colors4[sid];
}
#endif

fn load_color4(sid: u32) -> vec4<f32> {
#if WALK_LAYOUT
    return load_projected_row(sid, 3u);
#else
    return load_colors4_vec(sid);
#endif
}

fn load_normal_depth(sid: u32) -> vec4<f32> {
#if WALK_LAYOUT
    return load_colors4_vec(sid);
#else
    return load_projected_row(sid, 3u);
#endif
}

// A surfel's projection as a ProjectedSurfel (its normal and depth in the fourth vec4).
fn load_projected(sid: u32) -> ProjectedSurfel {
    return ProjectedSurfel(load_projected_row(sid, 0u), load_projected_row(sid, 1u), load_projected_row(sid, 2u),
                           load_normal_depth(sid));
}
