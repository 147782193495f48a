"""The numpy mirrors in gma/render/layouts.py match the WGSL structs byte for byte: a shader reads
each struct field and writes it out, and the values must come back unchanged. So do the constants the
Python side mirrors."""

from __future__ import annotations

import numpy as np
import pytest
import wgpu

from gma.render.layouts import DISPATCH_INFO, PROJECTED_SURFEL, RENDER_PARAMS, render_params
from gma.render.rasterizer import MAX_WORKGROUPS, RECORD_KEY_SHIFT, SURFEL_ID_BITS

pytestmark = pytest.mark.gpu

KERNEL = """
@group(0) @binding(0) var<uniform> params: RenderParams;
@group(0) @binding(1) var<storage, read> surfels: array<ProjectedSurfel>;
@group(0) @binding(2) var<storage, read> info: DispatchInfo;
@group(0) @binding(3) var<storage, read_write> out: array<f32>;

@compute @workgroup_size(1)
fn main() {
    for (var r = 0; r < 4; r++) {
        out[r] = params.w2c_r0[r]; out[4 + r] = params.w2c_r1[r]; out[8 + r] = params.w2c_r2[r];
        out[12 + r] = params.k_r0[r]; out[16 + r] = params.k_r1[r]; out[20 + r] = params.k_r2[r];
    }
    out[24] = f32(params.image_size.x); out[25] = f32(params.image_size.y);
    out[26] = f32(params.tile_grid.x); out[27] = f32(params.tile_grid.y);
    out[28] = f32(params.num_surfels); out[29] = f32(params.isect_capacity); out[30] = f32(params.num_channels);
    let s = surfels[1];
    for (var r = 0; r < 4; r++) {
        out[32 + r] = s.p_ref[r]; out[36 + r] = s.dp_dx[r]; out[40 + r] = s.dp_dy[r]; out[44 + r] = s.normal_depth[r];
    }
    out[48] = f32(info.groups_x); out[49] = f32(info.groups_y); out[50] = f32(info.groups_z);
    out[51] = f32(info.count);
    out[52] = f32(RECORD_KEY_SHIFT);
    out[53] = f32(TILE_KEY_MASK);
    out[54] = f32(SURFEL_ID_BITS);
}
"""


def test_struct_layouts_match_wgsl(gpu):
    view = np.arange(16, dtype=np.float32).reshape(4, 4) + 0.5
    K = np.array([[100, 0.25, 30], [0, 90, 20], [0, 0, 1]], np.float32)
    params = render_params(view, K, 37, 21, 1234, 5678, 3)
    surfels = np.zeros(2, PROJECTED_SURFEL)
    surfels[1]["p_ref"], surfels[1]["dp_dx"] = [1, 2, 3, 4], [5, 6, 7, 8]
    surfels[1]["dp_dy"], surfels[1]["normal_depth"] = [9, 10, 11, 12], [13, 14, 15, 16]
    info = np.zeros((), DISPATCH_INFO)
    info["groups"], info["count"] = (3, 1, 1), 4000
    code = gpu.shaders.source("common/render_types.wgsl") + KERNEL
    module = gpu.device.create_shader_module(code=code)
    pipeline = gpu.device.create_compute_pipeline(layout=wgpu.AutoLayoutMode.auto,
                                                  compute={"module": module, "entry_point": "main"})
    out = gpu.buffer(4 * 64, "out")
    uniform = gpu.upload(params, "params", wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
    bind = gpu.bind_group(pipeline, [uniform, gpu.upload(surfels, "s"), gpu.upload(info, "i"), out])
    enc = gpu.device.create_command_encoder()
    cp = enc.begin_compute_pass()
    cp.set_pipeline(pipeline)
    cp.set_bind_group(0, bind)
    cp.dispatch_workgroups(1)
    cp.end()
    gpu.submit(enc)
    got = gpu.read(out, np.float32, 64)
    np.testing.assert_array_equal(got[:12], view[:3].reshape(-1))
    np.testing.assert_array_equal(got[12:24].reshape(3, 4)[:, :3], K)
    np.testing.assert_array_equal(got[24:31], [37, 21, 3, 2, 1234, 5678, 3])
    np.testing.assert_array_equal(got[32:48], np.arange(1, 17))
    np.testing.assert_array_equal(got[48:52], [3, 1, 1, 4000])
    assert RENDER_PARAMS.itemsize == 128 and PROJECTED_SURFEL.itemsize == 64
    np.testing.assert_array_equal(got[52:55], [RECORD_KEY_SHIFT, (1 << RECORD_KEY_SHIFT) - 1, SURFEL_ID_BITS])
    assert MAX_WORKGROUPS * 256 <= 1 << SURFEL_ID_BITS, "the renderer's surfel limit must keep ids below the block bits"
