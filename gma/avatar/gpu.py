"""GPU path for showing an avatar: the decoded surfels are uploaded once (per load or edit), and every
frame only the bone transforms go to the GPU, where ``GpuPoser`` skins the morphed mesh and places the
surfels straight into the renderer's buffers (no per-frame readback until an image is wanted)."""

from __future__ import annotations

import numpy as np
import torch

from gma.avatar.avatar import Avatar
from gma.avatar.model import DecodedAvatar
from gma.body.gpu_posing import GpuPoser
from gma.render import SurfelBuffers, SurfelRasterizer, read_outputs

__all__ = ["AvatarRenderer"]


class AvatarRenderer:
    """Offline renderer of one avatar (videos, evaluation previews).

        r = AvatarRenderer(ctx, avatar, body)
        img = r.render(params, camera, background)     # float32 [H, W, 3]
    """

    def __init__(self, ctx, avatar: Avatar, body, decoded: DecodedAvatar | None = None):
        self.ctx, self.avatar, self.body = ctx, avatar, body
        self.decoded = decoded or avatar.decode()
        self.poser = GpuPoser(ctx, body.faces, body.skin_indices, body.skin_weights)
        self.poser.set_surfels(self.decoded.binding)
        n = len(self.decoded.binding)
        self.surfels = SurfelBuffers.allocate(ctx, n, 3)
        ctx.write(self.surfels.colors, self.decoded.colors.numpy().astype(np.float32))
        ctx.write(self.surfels.opacities, self.decoded.opacities.numpy().astype(np.float32))
        self.rasterizer = SurfelRasterizer(ctx)
        self._rest_key = None

    def update_rows(self, rows, mesh: bool = False) -> None:
        """Upload the surfel rows [R] of ``self.decoded`` that an edit changed (binding and colour; one
        write per buffer covering the rows' span, not the whole avatar), and with ``mesh`` the mesh layer
        (the rest vertices are re-uploaded by the next :meth:`set_params`)."""
        from gma.body.placement import SurfelBinding, pack_surfel_local

        rows = torch.as_tensor(rows, dtype=torch.long)
        if len(rows):
            lo, hi = int(rows.min()), int(rows.max()) + 1
            b = self.decoded.binding
            span = SurfelBinding(b.face_id[lo:hi], b.uv[lo:hi], b.offset[lo:hi], b.scale[lo:hi], b.quat[lo:hi])
            packed = pack_surfel_local(span)
            self.ctx.write(self.poser.surfels_buf, packed, lo * packed.dtype.itemsize)
            self.ctx.write(self.surfels.colors, self.decoded.colors[lo:hi].numpy().astype(np.float32), lo * 12)
        if mesh:
            self._rest_key = None

    def set_params(self, params: dict) -> None:
        """Pose for body ``params`` (shape defaults to the avatar's identity): rest vertices are uploaded
        only when shape or expression change, bone transforms every call."""
        params = self.body.check_params({"shape": self.avatar.shape, **params})
        key = params["shape"].numpy().tobytes() + params["expression"].numpy().tobytes()
        with torch.no_grad():
            if key != self._rest_key:
                rest = self.body.rest_vertices(params) + self.decoded.vertex_offsets
                self.poser.set_rest_vertices(rest)
                self._rest_key = key
            self.poser.pose(self.body.bone_transforms(params), self.surfels.means, self.surfels.quats,
                            self.surfels.scales)

    def render(self, params: dict, camera, background=(1.0, 1.0, 1.0)) -> np.ndarray:
        """Posed render as float32 [H, W, 3] (reads the image back)."""
        self.set_params(params)
        state = self.rasterizer.forward(self.surfels, camera, np.asarray(background, np.float32), replay=False)
        return read_outputs(self.ctx, state).color

