"""Offscreen rasteriser for textured triangle meshes through a wgpu render pipeline.

Used to render synthetic ground truth (``gma synth``); independent of the surfel renderer so that
the data a fit is measured against does not share that renderer's bugs. Anti-aliasing is by
supersampling: the mesh is drawn at ``supersample``× the resolution and box-filtered, which also
filters texture detail finer than a pixel, and the coverage becomes a soft mask like a matting
network's output.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import wgpu

from gma.core.camera import projection_matrix
from gma.gpu import GpuContext

__all__ = ["MeshRasterizer", "TexturedMesh", "vertex_normals"]

_SHADER = "synth/mesh.wgsl"
_STRIDE = 8 * 4  # position (3), normal (3), uv (2) float32 per triangle corner


@dataclass
class TexturedMesh:
    """Topology and texture of a mesh whose vertex positions change per frame.

    ``faces`` [F, 3] int vertex indices (counter-clockwise seen from outside); ``face_uvs`` [F, 3, 2]
    texture coordinates per corner (u right, v up, in [0, 1]); ``texture`` [Ht, Wt, 3] uint8 sRGB.
    """

    faces: np.ndarray
    face_uvs: np.ndarray
    texture: np.ndarray

    def __post_init__(self):
        self.faces = np.ascontiguousarray(self.faces, dtype=np.int64)
        self.face_uvs = np.ascontiguousarray(self.face_uvs, dtype=np.float32)
        if self.faces.ndim != 2 or self.faces.shape[1] != 3:
            raise ValueError(f"faces must be [F, 3], got {self.faces.shape}")
        if self.face_uvs.shape != (len(self.faces), 3, 2):
            raise ValueError(
                f"face_uvs must be [F, 3, 2] = {(len(self.faces), 3, 2)}, got {self.face_uvs.shape}"
            )
        if self.texture.ndim != 3 or self.texture.shape[2] != 3 or self.texture.dtype != np.uint8:
            raise ValueError("texture must be uint8 [Ht, Wt, 3]")


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals [V, 3] (unit length; zero for unused vertices)."""
    v = vertices.astype(np.float64)
    fn = np.cross(v[faces[:, 1]] - v[faces[:, 0]], v[faces[:, 2]] - v[faces[:, 0]])
    n = np.zeros_like(v)
    for k in range(3):
        np.add.at(n, faces[:, k], fn)
    length = np.linalg.norm(n, axis=1, keepdims=True)
    return (n / np.maximum(length, 1e-20)).astype(np.float32)


class MeshRasterizer:
    """Draws one :class:`TexturedMesh` at ``width``×``height`` with a given pose of its vertices.

    The pipeline, texture and render targets are made once; each :meth:`render` uploads the vertex
    stream, draws, and reads the image back (this is an offline tool, so a readback per frame is fine).
    """

    def __init__(
        self,
        ctx: GpuContext,
        mesh: TexturedMesh,
        width: int,
        height: int,
        supersample: int = 3,
        shading: float = 0.35,
        light_dir=(0.3, 0.8, 0.5),
    ):
        if width <= 0 or height <= 0 or supersample < 1:
            raise ValueError("width, height and supersample must be positive")
        self.ctx, self.mesh = ctx, mesh
        self.width, self.height, self.ss = int(width), int(height), int(supersample)
        self.rw, self.rh = self.width * self.ss, self.height * self.ss
        max_dim = int(ctx.device.limits["max-texture-dimension-2d"])
        if max(self.rw, self.rh) > max_dim:
            raise ValueError(
                f"{self.rw}x{self.rh} render target exceeds the device limit {max_dim}; "
                "lower the supersampling"
            )
        light = np.asarray(light_dir, np.float64)
        self.light = np.append(light / np.linalg.norm(light), float(shading)).astype(np.float32)
        dev = ctx.device
        self.pipeline = self._pipeline()
        tex_h, tex_w = mesh.texture.shape[:2]
        self.texture = dev.create_texture(
            label="synth albedo",
            size=(tex_w, tex_h, 1),
            format=wgpu.TextureFormat.rgba8unorm,
            usage=wgpu.TextureUsage.TEXTURE_BINDING | wgpu.TextureUsage.COPY_DST,
        )
        rgba = np.ascontiguousarray(np.dstack([mesh.texture, np.full((tex_h, tex_w), 255, np.uint8)]))
        dev.queue.write_texture(
            {"texture": self.texture},
            rgba,
            {"bytes_per_row": tex_w * 4, "rows_per_image": tex_h},
            (tex_w, tex_h, 1),
        )
        sampler = dev.create_sampler(
            mag_filter="linear",
            min_filter="linear",
            address_mode_u="clamp-to-edge",
            address_mode_v="clamp-to-edge",
        )
        self.uniforms = ctx.buffer(
            3 * 64, "synth uniforms", wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST
        )
        self.bind_group = dev.create_bind_group(
            layout=self.pipeline.get_bind_group_layout(0),
            entries=[
                {
                    "binding": 0,
                    "resource": {"buffer": self.uniforms, "offset": 0, "size": self.uniforms.size},
                },
                {"binding": 1, "resource": self.texture.create_view()},
                {"binding": 2, "resource": sampler},
            ],
        )
        n_corners = 3 * len(mesh.faces)
        self.vertices = ctx.buffer(
            max(n_corners, 1) * _STRIDE, "synth vertices", wgpu.BufferUsage.VERTEX | wgpu.BufferUsage.COPY_DST
        )
        self.color = dev.create_texture(
            label="synth colour",
            size=(self.rw, self.rh, 1),
            format=wgpu.TextureFormat.rgba8unorm,
            usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC,
        )
        self.depth = dev.create_texture(
            label="synth depth",
            size=(self.rw, self.rh, 1),
            format=wgpu.TextureFormat.depth32float,
            usage=wgpu.TextureUsage.RENDER_ATTACHMENT,
        )
        self.row_bytes = (self.rw * 4 + 255) // 256 * 256  # copies need 256-byte aligned rows
        self.readback = ctx.buffer(
            self.row_bytes * self.rh, "synth readback", wgpu.BufferUsage.COPY_DST | wgpu.BufferUsage.MAP_READ
        )

    def _pipeline(self) -> wgpu.GPURenderPipeline:
        module = self.ctx.shaders.module(self.ctx.device, _SHADER)
        attrs = [
            {"format": wgpu.VertexFormat.float32x3, "offset": 0, "shader_location": 0},
            {"format": wgpu.VertexFormat.float32x3, "offset": 12, "shader_location": 1},
            {"format": wgpu.VertexFormat.float32x2, "offset": 24, "shader_location": 2},
        ]
        return self.ctx.device.create_render_pipeline(
            label=_SHADER,
            layout=wgpu.AutoLayoutMode.auto,
            vertex={
                "module": module,
                "entry_point": "vs_main",
                "buffers": [{"array_stride": _STRIDE, "step_mode": "vertex", "attributes": attrs}],
            },
            # No culling: garments are open surfaces whose inside can be seen through a loose cuff.
            primitive={"topology": wgpu.PrimitiveTopology.triangle_list, "cull_mode": wgpu.CullMode.none},
            depth_stencil={
                "format": wgpu.TextureFormat.depth32float,
                "depth_write_enabled": True,
                "depth_compare": wgpu.CompareFunction.less,
            },
            multisample={"count": 1},
            fragment={
                "module": module,
                "entry_point": "fs_main",
                "targets": [{"format": wgpu.TextureFormat.rgba8unorm}],
            },
        )

    def render(
        self, vertices: np.ndarray, K: np.ndarray, w2c: np.ndarray, background=(0.5, 0.5, 0.5)
    ) -> tuple[np.ndarray, np.ndarray]:
        """Draw the mesh with world-space ``vertices`` [V, 3] (metres) seen by the OpenCV camera
        (``K`` [3, 3] in pixels of the output image, ``w2c`` [4, 4]).

        Returns ``image`` uint8 [H, W, 3] composited over ``background`` (RGB in [0, 1]) and ``mask``
        float32 [H, W] in [0, 1], the fraction of each pixel the mesh covers.
        """
        faces = self.mesh.faces
        vertices = np.asarray(vertices, np.float32)
        if vertices.ndim != 2 or vertices.shape[1] != 3 or (faces.size and faces.max() >= len(vertices)):
            raise ValueError(
                f"vertices must be [V, 3] covering the mesh's face indices, got {vertices.shape}"
            )
        ctx, dev = self.ctx, self.ctx.device
        if faces.size:
            normals = vertex_normals(vertices, faces)
            stream = np.concatenate([vertices[faces], normals[faces], self.mesh.face_uvs], axis=2)
            ctx.write(self.vertices, stream.astype(np.float32))
        # Scale the intrinsics to the supersampled target: pixel centres stay at +0.5 in both.
        S = np.diag([self.ss, self.ss, 1.0])
        proj = projection_matrix(S @ np.asarray(K, np.float64), self.rw, self.rh)
        # WGSL matrices are column-major: upload the transposes.
        uni = np.concatenate(
            [np.asarray(w2c, np.float32).T.ravel(), proj.astype(np.float32).T.ravel(), self.light]
        )
        ctx.write(self.uniforms, uni.astype(np.float32))

        enc = dev.create_command_encoder(label="synth draw")
        rp = enc.begin_render_pass(
            color_attachments=[
                {
                    "view": self.color.create_view(),
                    "clear_value": (0, 0, 0, 0),
                    "load_op": wgpu.LoadOp.clear,
                    "store_op": wgpu.StoreOp.store,
                }
            ],
            depth_stencil_attachment={
                "view": self.depth.create_view(),
                "depth_clear_value": 1.0,
                "depth_load_op": wgpu.LoadOp.clear,
                "depth_store_op": wgpu.StoreOp.store,
            },
        )
        if faces.size:
            rp.set_pipeline(self.pipeline)
            rp.set_bind_group(0, self.bind_group)
            rp.set_vertex_buffer(0, self.vertices)
            rp.draw(3 * len(faces))
        rp.end()
        enc.copy_texture_to_buffer(
            {"texture": self.color},
            {"buffer": self.readback, "bytes_per_row": self.row_bytes, "rows_per_image": self.rh},
            (self.rw, self.rh, 1),
        )
        ctx.submit(enc)
        self.readback.map_sync(wgpu.MapMode.READ)
        try:
            raw = np.frombuffer(self.readback.read_mapped(), np.uint8).copy()
        finally:
            self.readback.unmap()
        big = raw.reshape(self.rh, self.row_bytes)[:, : self.rw * 4].reshape(self.rh, self.rw, 4)
        # Box filter ss×ss blocks; cleared pixels are (0, 0, 0, 0), so the mean is premultiplied colour.
        s = self.ss
        mean = big.reshape(self.height, s, self.width, s, 4).astype(np.float32).mean(axis=(1, 3)) / 255.0
        alpha = mean[..., 3]
        rgb = mean[..., :3] + (1.0 - alpha[..., None]) * np.asarray(background, np.float32)
        image = np.clip(np.rint(rgb * 255.0), 0, 255).astype(np.uint8)
        return image, alpha
