"""Render pipelines of the viewer (blit, mesh overlays, screen lines, screen images), built once per target format and
cached, and the OpenCV-camera -> WebGPU clip-space matrix they share."""

from __future__ import annotations

import numpy as np
import wgpu

from gma.core.camera import Camera
from gma.gpu import GpuContext

__all__ = ["DEPTH_FORMAT", "ViewerPipelines", "clip_matrix"]

DEPTH_FORMAT = wgpu.TextureFormat.depth32float
OVERLAY_PARAMS_BYTES = 96  # mat4x4 + vec4 colour + vec4 settings
_ALPHA_BLEND = {
    "color": {"src_factor": "src-alpha", "dst_factor": "one-minus-src-alpha", "operation": "add"},
    "alpha": {"src_factor": "one", "dst_factor": "one-minus-src-alpha", "operation": "add"},
}


def clip_matrix(camera: Camera, near: float, far: float) -> np.ndarray:
    """[4, 4] world -> clip matrix for an OpenCV camera (x right, y down, z forward; pixel centres at
    +0.5), so that rasterised geometry lands on the same pixels as the surfel renderer's output.
    WebGPU clip space: x, y in [-w, w] with y up, depth z/w in [0, 1] between ``near`` and ``far``."""
    K, W, H = camera.K.astype(np.float64), camera.width, camera.height
    P = np.zeros((4, 4))
    P[0, :3] = [2 * K[0, 0] / W, 2 * K[0, 1] / W, 2 * K[0, 2] / W - 1]
    P[1, :3] = [0.0, -2 * K[1, 1] / H, 1 - 2 * K[1, 2] / H]
    P[2, 2:] = [far / (far - near), -near * far / (far - near)]
    P[3, 2] = 1.0
    return (P @ camera.viewmat.astype(np.float64)).astype(np.float32)


class ViewerPipelines:
    """Pipelines for one device, keyed by (kind, target format); a frame builds none."""

    def __init__(self, ctx: GpuContext):
        self.ctx = ctx
        dev = ctx.device
        self._cache: dict[tuple[str, str], wgpu.GPURenderPipeline] = {}
        vis = wgpu.ShaderStage.VERTEX | wgpu.ShaderStage.FRAGMENT
        ro = {"type": wgpu.BufferBindingType.read_only_storage}
        self.overlay_layout = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": vis, "buffer": {"type": wgpu.BufferBindingType.uniform}},
            {"binding": 1, "visibility": wgpu.ShaderStage.VERTEX, "buffer": ro},
            {"binding": 2, "visibility": wgpu.ShaderStage.VERTEX, "buffer": ro},
            {"binding": 3, "visibility": wgpu.ShaderStage.VERTEX, "buffer": ro},
        ])
        self.blit_layout = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": wgpu.ShaderStage.FRAGMENT,
             "texture": {"sample_type": wgpu.TextureSampleType.float}},
        ])
        self.blit_scaled_layout = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": wgpu.ShaderStage.FRAGMENT,
             "texture": {"sample_type": wgpu.TextureSampleType.float}},
            {"binding": 1, "visibility": wgpu.ShaderStage.FRAGMENT, "sampler": {"type": "filtering"}},
        ])
        self.lines_layout = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": vis, "buffer": {"type": wgpu.BufferBindingType.uniform}},
        ])
        self.image_layout = dev.create_bind_group_layout(entries=[
            {"binding": 0, "visibility": vis, "buffer": {"type": wgpu.BufferBindingType.uniform}},
            {"binding": 1, "visibility": wgpu.ShaderStage.FRAGMENT,
             "texture": {"sample_type": wgpu.TextureSampleType.float}},
            {"binding": 2, "visibility": wgpu.ShaderStage.FRAGMENT, "sampler": {"type": "filtering"}},
        ])

    def get(self, kind: str, fmt: str) -> wgpu.GPURenderPipeline:
        key = (kind, str(fmt))
        p = self._cache.get(key)
        if p is None:
            p = self._cache[key] = self._build(kind, str(fmt))
        return p

    def _build(self, kind: str, fmt: str) -> wgpu.GPURenderPipeline:
        dev, shaders = self.ctx.device, self.ctx.shaders
        depth = {"format": DEPTH_FORMAT, "depth_write_enabled": False, "depth_compare": wgpu.CompareFunction.always}
        target = {"format": fmt}
        topology = wgpu.PrimitiveTopology.triangle_list
        buffers: list = []
        if kind in ("blit", "blit_scaled"):
            module = shaders.module(dev, "viewer/blit.wgsl", {"SRGB_TARGET": fmt.endswith("-srgb")})
            layout, vs, fs = self.blit_layout, "vs_main", "fs_main"
            if kind == "blit_scaled":
                layout, fs = self.blit_scaled_layout, "fs_scaled"
        elif kind == "lines":
            module = shaders.module(dev, "viewer/screen_lines.wgsl")
            layout, vs, fs = self.lines_layout, "vs_main", "fs_main"
            topology = wgpu.PrimitiveTopology.line_strip
            buffers = [{"array_stride": 8, "attributes": [{"format": "float32x2", "offset": 0, "shader_location": 0}]}]
        elif kind == "image":
            module = shaders.module(dev, "viewer/screen_image.wgsl")
            layout, vs, fs = self.image_layout, "vs_main", "fs_main"
            target = {"format": fmt, "blend": _ALPHA_BLEND}
            buffers = [{"array_stride": 16, "attributes": [
                {"format": "float32x2", "offset": 0, "shader_location": 0},
                {"format": "float32x2", "offset": 8, "shader_location": 1}]}]
        else:
            module = shaders.module(dev, "viewer/mesh_overlay.wgsl")
            layout, fs = self.overlay_layout, "fs_color"
            vs = {"depth": "vs_depth", "wire": "vs_wire", "highlight": "vs_highlight", "normals": "vs_normals",
                  "coarse": "vs_coarse"}[kind]
            depth = {"format": DEPTH_FORMAT, "depth_write_enabled": kind in ("depth", "coarse"),
                     "depth_compare": wgpu.CompareFunction.less_equal}
            if kind == "depth":
                target = {"format": fmt, "write_mask": 0}
            elif kind == "coarse":
                fs = "fs_disc"
            else:
                target = {"format": fmt, "blend": _ALPHA_BLEND}
            if kind in ("wire", "normals"):
                topology = wgpu.PrimitiveTopology.line_list
        return dev.create_render_pipeline(
            label=f"viewer.{kind}",
            layout=dev.create_pipeline_layout(bind_group_layouts=[layout]),
            vertex={"module": module, "entry_point": vs, "buffers": buffers},
            primitive={"topology": topology, "cull_mode": wgpu.CullMode.none},
            depth_stencil=depth,
            multisample={"count": 1},
            fragment={"module": module, "entry_point": fs, "targets": [target]},
        )
