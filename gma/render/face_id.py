"""Face-ID render: for a camera and posed vertices, the visible face at every pixel and its depth.

This is the visibility test of editing (a brush or box selects only faces that are actually seen: an arm
in front of the torso hides the torso's faces; a stamp changes only surfels at the visible depth) and the
region map of ``gma eval``'s per-region scores (:mod:`gma.train.regions`).
The fixed-function pipeline with a depth buffer does the work (``shaders/wgsl/edit/face_id.wgsl``);
``face_id_reference`` is its numpy twin for tests (a per-triangle z-buffer, slow, tiny meshes only).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import wgpu

from gma.core.camera import Camera, projection_matrix
from gma.gpu import GpuContext

__all__ = ["FaceIdRenderer", "IdImage", "face_id_reference"]

_SHADER = "edit/face_id.wgsl"
_NEAR, _FAR = 0.01, 100.0


@dataclass
class IdImage:
    """``ids`` [H, W] int64 face index (-1 where no face), ``depth`` [H, W] float32 camera z in metres
    (inf where no face), and the ``camera`` they were rendered with."""

    ids: np.ndarray
    depth: np.ndarray
    camera: Camera

    def mask(self, face_mask: np.ndarray) -> np.ndarray:
        """[H, W] bool: pixels showing a face for which ``face_mask`` [F] is True."""
        fm = np.asarray(face_mask, bool)
        return np.where(self.ids >= 0, fm[np.clip(self.ids, 0, None)], False)


class FaceIdRenderer:
    """Renders face ids and depth of one mesh topology. Pipelines are made once; each :meth:`render`
    uploads the posed vertices [V, 3], draws and reads back two r32 images (a user action, not a frame
    loop, so the readback is fine)."""

    def __init__(self, ctx: GpuContext, faces):
        self.ctx = ctx
        faces = np.ascontiguousarray(np.asarray(faces, np.uint32).reshape(-1, 3))
        self.num_faces = len(faces)
        self.faces_buf = ctx.upload(faces if faces.size else np.zeros(3, np.uint32), "edit.faces")
        self.uniforms = ctx.buffer(2 * 64, "edit.id_uniforms", wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
        self.pipeline = self._pipeline()
        self._targets: dict[tuple[int, int], tuple] = {}
        self._vert_buf = None

    def _pipeline(self) -> wgpu.GPURenderPipeline:
        dev = self.ctx.device
        module = self.ctx.shaders.module(dev, _SHADER)
        return dev.create_render_pipeline(
            label=_SHADER, layout=wgpu.AutoLayoutMode.auto,
            vertex={"module": module, "entry_point": "vs_main", "buffers": []},
            # Both sides: a selection through a loose cuff must see the inside faces it shows.
            primitive={"topology": wgpu.PrimitiveTopology.triangle_list, "cull_mode": wgpu.CullMode.none},
            depth_stencil={"format": wgpu.TextureFormat.depth32float, "depth_write_enabled": True,
                           "depth_compare": wgpu.CompareFunction.less},
            multisample={"count": 1},
            fragment={"module": module, "entry_point": "fs_main",
                      "targets": [{"format": wgpu.TextureFormat.r32uint}, {"format": wgpu.TextureFormat.r32float}]},
        )

    def _targets_for(self, width: int, height: int) -> tuple:
        key = (width, height)
        if key not in self._targets:
            dev = self.ctx.device
            usage = wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC
            ids = dev.create_texture(label="edit.ids", size=(width, height, 1), format=wgpu.TextureFormat.r32uint,
                                     usage=usage)
            z = dev.create_texture(label="edit.z", size=(width, height, 1), format=wgpu.TextureFormat.r32float,
                                   usage=usage)
            depth = dev.create_texture(label="edit.depth", size=(width, height, 1),
                                       format=wgpu.TextureFormat.depth32float,
                                       usage=wgpu.TextureUsage.RENDER_ATTACHMENT)
            row = (width * 4 + 255) // 256 * 256  # texture copies need 256-byte aligned rows
            readback = self.ctx.buffer(2 * row * height, "edit.id_readback",
                                       wgpu.BufferUsage.COPY_DST | wgpu.BufferUsage.COPY_SRC)
            self._targets = {key: (ids, z, depth, readback, row)}  # keep one size: the viewer's window
        return self._targets[key]

    def render(self, vertices, camera: Camera) -> IdImage:
        """Face ids and depth of the mesh with world ``vertices`` [V, 3] (m) seen by ``camera``."""
        ctx, dev = self.ctx, self.ctx.device
        w, h = int(camera.width), int(camera.height)
        verts = np.ascontiguousarray(np.asarray(vertices, np.float32).reshape(-1))
        if self._vert_buf is None or self._vert_buf.size < max(verts.nbytes, 4):
            self._vert_buf = ctx.buffer(max(verts.nbytes, 4), "edit.vertices")
            self._bind = dev.create_bind_group(layout=self.pipeline.get_bind_group_layout(0), entries=[
                {"binding": 0, "resource": {"buffer": self.uniforms, "offset": 0, "size": self.uniforms.size}},
                {"binding": 1, "resource": {"buffer": self._vert_buf, "offset": 0, "size": self._vert_buf.size}},
                {"binding": 2, "resource": {"buffer": self.faces_buf, "offset": 0, "size": self.faces_buf.size}}])
        ctx.write(self._vert_buf, verts)
        proj = projection_matrix(np.asarray(camera.K, np.float64), w, h, _NEAR, _FAR)
        # WGSL matrices are column-major: upload the transposes.
        ctx.write(self.uniforms, np.concatenate([np.asarray(camera.viewmat, np.float32).T.ravel(),
                                                 proj.astype(np.float32).T.ravel()]))
        ids_t, z_t, depth_t, readback, row = self._targets_for(w, h)
        enc = dev.create_command_encoder(label="edit face ids")
        rp = enc.begin_render_pass(
            color_attachments=[
                {"view": ids_t.create_view(), "clear_value": (0, 0, 0, 0), "load_op": wgpu.LoadOp.clear,
                 "store_op": wgpu.StoreOp.store},
                {"view": z_t.create_view(), "clear_value": (np.inf, 0, 0, 0), "load_op": wgpu.LoadOp.clear,
                 "store_op": wgpu.StoreOp.store}],
            depth_stencil_attachment={"view": depth_t.create_view(), "depth_clear_value": 1.0,
                                      "depth_load_op": wgpu.LoadOp.clear, "depth_store_op": wgpu.StoreOp.store})
        if self.num_faces:
            rp.set_pipeline(self.pipeline)
            rp.set_bind_group(0, self._bind)
            rp.draw(3 * self.num_faces)
        rp.end()
        for i, tex in enumerate((ids_t, z_t)):
            enc.copy_texture_to_buffer({"texture": tex},
                                       {"buffer": readback, "offset": i * row * h, "bytes_per_row": row,
                                        "rows_per_image": h}, (w, h, 1))
        ctx.submit(enc)
        raw = ctx.read(readback, np.uint8)
        planes = raw.reshape(2, h, row)[:, :, : 4 * w]
        ids = planes[0].copy().view(np.uint32).reshape(h, w).astype(np.int64) - 1
        depth = planes[1].copy().view(np.float32).reshape(h, w)
        depth = np.where(ids >= 0, depth, np.inf).astype(np.float32)
        return IdImage(ids, depth, camera)


def face_id_reference(vertices, faces, camera: Camera) -> IdImage:
    """Numpy twin of :meth:`FaceIdRenderer.render`: pixel centres at +0.5, perspective-correct camera z,
    nearest face wins (depth in NDC like the GPU, ties to the lower face index). Loops over faces: for
    test meshes of tens of faces only."""
    v = np.asarray(vertices, np.float64)
    f = np.asarray(faces, np.int64).reshape(-1, 3)
    w, h = int(camera.width), int(camera.height)
    R, t = np.asarray(camera.viewmat, np.float64)[:3, :3], np.asarray(camera.viewmat, np.float64)[:3, 3]
    pc = v @ R.T + t
    proj = projection_matrix(np.asarray(camera.K, np.float64), w, h, _NEAR, _FAR)
    clip = np.c_[pc, np.ones(len(pc))] @ proj.T
    ndc_z = clip[:, 2] / clip[:, 3]
    px = np.stack([(clip[:, 0] / clip[:, 3] + 1) * 0.5 * w, (1 - clip[:, 1] / clip[:, 3]) * 0.5 * h], 1)
    ys, xs = np.mgrid[0:h, 0:w] + 0.5
    best = np.full((h, w), np.inf)
    ids = np.full((h, w), -1, np.int64)
    depth = np.full((h, w), np.inf, np.float32)
    for i, (a, b, c) in enumerate(f):
        if min(pc[a, 2], pc[b, 2], pc[c, 2]) <= _NEAR:
            continue  # the GPU clips these; tests keep meshes in front of the camera
        (x0, y0), (x1, y1), (x2, y2) = px[a], px[b], px[c]
        area = (x1 - x0) * (y2 - y0) - (x2 - x0) * (y1 - y0)
        if abs(area) < 1e-12:
            continue
        l0 = ((x1 - xs) * (y2 - ys) - (x2 - xs) * (y1 - ys)) / area
        l1 = ((x2 - xs) * (y0 - ys) - (x0 - xs) * (y2 - ys)) / area
        l2 = 1 - l0 - l1
        inside = (l0 >= 0) & (l1 >= 0) & (l2 >= 0)
        zn = l0 * ndc_z[a] + l1 * ndc_z[b] + l2 * ndc_z[c]  # NDC depth is affine in screen space
        inv = l0 / pc[a, 2] + l1 / pc[b, 2] + l2 / pc[c, 2]  # 1/z too (perspective-correct z)
        win = inside & (zn < best) & (zn >= 0) & (zn <= 1)
        best[win] = zn[win]
        ids[win] = i
        depth[win] = (1.0 / inv[win]).astype(np.float32)
    return IdImage(ids, depth, camera)
