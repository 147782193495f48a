"""GPU posing: linear-blend skinning of the (morphed) rest mesh, then surfel placement, written straight
into the renderer's input buffers (``means`` [N*3], ``quats`` [N*4], ``scales`` [N*2], packed float32).

Per frame only the bone transforms (J × 48 bytes) go to the GPU and nothing comes back; the rest
vertices and surfel bindings are uploaded when they change (avatar load, edit, shape or expression
change). The torch twins are ``gma.body.skinning.linear_blend_skinning`` and
``gma.body.placement.place_surfels``.

    poser = GpuPoser(ctx, body.faces, body.skin_indices, body.skin_weights)
    poser.set_rest_vertices(rest)                 # [V, 3], e.g. morph_vertices(body rest, offsets)
    poser.set_surfels(binding)                    # SurfelBinding of N surfels
    poser.pose(bone_transforms, means, quats, scales)   # encodes + submits, no readback
"""

from __future__ import annotations

import numpy as np
import torch
import wgpu

from gma.body.placement import SurfelBinding, pack_surfel_local

__all__ = ["GpuPoser"]

WG = 256
_UNIFORM = wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST


def _groups(count: int, max_per_dim: int) -> tuple[int, int]:
    """(x, y) workgroup counts covering ``count`` items; the kernels flatten (x, y) back to an index."""
    n = max(1, -(-count // WG))
    x = min(n, max_per_dim)
    return x, -(-n // x)


def _as_np(x, dtype) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        x = x.detach().cpu().numpy()
    return np.ascontiguousarray(np.asarray(x, dtype=dtype))


class GpuPoser:
    """Owns the body posing pipelines and intermediate buffers for one mesh.

    faces [F, 3], skin_indices [V, K], skin_weights [V, K] are fixed at construction (the topology
    and rig); rest vertices, surfels and bone transforms are set per use.
    """

    def __init__(self, ctx, faces, skin_indices, skin_weights):
        self.ctx = ctx
        faces = _as_np(faces, np.int64)
        idx = _as_np(skin_indices, np.int64)
        w = _as_np(skin_weights, np.float32)
        if faces.ndim != 2 or faces.shape[1] != 3:
            raise ValueError(f"faces must be [F, 3], got {faces.shape}")
        if idx.shape != w.shape or idx.ndim != 2:
            raise ValueError(f"skin_indices {idx.shape} and skin_weights {w.shape} must both be [V, K]")
        self.num_vertices, self.k = idx.shape
        self.num_faces = faces.shape[0]
        if self.num_faces and (faces.min() < 0 or faces.max() >= self.num_vertices):
            raise ValueError(f"faces index vertices outside [0, {self.num_vertices})")
        self.num_bones = int(idx.max()) + 1 if idx.size else 1
        self._max_groups = int(ctx.limits["max-compute-workgroups-per-dimension"])

        self.skin_pipeline = ctx.compute_pipeline("body/skin.wgsl", defines={"WG": WG})
        self.place_pipeline = ctx.compute_pipeline("body/place.wgsl", defines={"WG": WG})

        self.faces_buf = ctx.upload(faces.astype(np.uint32), "body.faces")
        self.skin_indices_buf = ctx.upload(idx.astype(np.uint32), "body.skin_indices")
        self.skin_weights_buf = ctx.upload(w, "body.skin_weights")
        self.rest_buf = ctx.buffer(12 * self.num_vertices, "body.rest_vertices")
        self.posed_buf = ctx.buffer(12 * self.num_vertices, "body.posed_vertices")
        self.bones_buf = ctx.buffer(48 * self.num_bones, "body.bones")
        self.skin_params = ctx.buffer(16, "body.skin_params", _UNIFORM)
        self.place_params = ctx.buffer(16, "body.place_params", _UNIFORM)
        ctx.write(self.skin_params, np.array([self.num_vertices, self.k, self.num_bones, 0], np.uint32))
        self.skin_bind = ctx.bind_group(
            self.skin_pipeline,
            [self.skin_params, self.rest_buf, self.skin_indices_buf, self.skin_weights_buf, self.bones_buf,
             self.posed_buf],
        )
        self.num_surfels = 0
        self.surfels_buf = None
        self._place_binds: dict[tuple[int, int, int], object] = {}
        self._has_rest = False

    # -- inputs -----------------------------------------------------------------------------------
    def set_rest_vertices(self, rest_vertices) -> None:
        """Upload the canonical (morphed) vertices [V, 3] (m)."""
        rest = _as_np(rest_vertices, np.float32)
        if rest.shape != (self.num_vertices, 3):
            raise ValueError(f"rest_vertices must be [{self.num_vertices}, 3], got {list(rest.shape)}")
        self.ctx.write(self.rest_buf, rest)
        self._has_rest = True

    def set_surfels(self, binding: SurfelBinding) -> None:
        """Upload the surfel bindings (N surfels); output buffers passed to :meth:`pose` must then hold
        at least N surfels."""
        binding.validate(self.num_faces)
        packed = pack_surfel_local(binding)
        self.num_surfels = len(binding)
        self.surfels_buf = self.ctx.upload(packed, "body.surfels")
        self.ctx.write(self.place_params, np.array([self.num_surfels, 0, 0, 0], np.uint32))
        self._place_binds.clear()

    def set_bone_transforms(self, bone_transforms) -> None:
        """Upload [J, 4, 4] rest→posed transforms (the bottom rows are ignored)."""
        t = _as_np(bone_transforms, np.float32)
        if t.ndim != 3 or t.shape[1:] != (4, 4) or t.shape[0] < self.num_bones:
            raise ValueError(f"bone_transforms must be [J >= {self.num_bones}, 4, 4], got {list(t.shape)}")
        self.ctx.write(self.bones_buf, np.ascontiguousarray(t[: self.num_bones, :3, :]))

    # -- per frame ----------------------------------------------------------------------------------
    def encode(self, encoder, means, quats, scales) -> None:
        """Record skinning + placement into ``encoder`` (uses the last uploaded transforms)."""
        if not self._has_rest:
            raise RuntimeError("GpuPoser: call set_rest_vertices() before posing")
        if self.surfels_buf is None:
            raise RuntimeError("GpuPoser: call set_surfels() before posing")
        n = self.num_surfels
        for name, buf, width in (("means", means, 3), ("quats", quats, 4), ("scales", scales, 2)):
            if buf.size < 4 * width * n:
                raise ValueError(f"{name} buffer holds {buf.size} bytes, {n} surfels need {4 * width * n}")
        key = (id(means), id(quats), id(scales))
        bind = self._place_binds.get(key)
        if bind is None and n:
            bind = self.ctx.bind_group(
                self.place_pipeline,
                [self.place_params, self.posed_buf, self.faces_buf, self.surfels_buf, means, quats, scales],
            )
            self._place_binds[key] = bind
        # Both dispatches in one compute pass: wgpu orders storage-buffer writes of one dispatch before
        # reads in the next within a pass, so the placement sees the skinned vertices.
        p = encoder.begin_compute_pass(label="body.pose")
        if self.num_vertices:
            p.set_pipeline(self.skin_pipeline)
            p.set_bind_group(0, self.skin_bind)
            p.dispatch_workgroups(*_groups(self.num_vertices, self._max_groups))
        if n:
            p.set_pipeline(self.place_pipeline)
            p.set_bind_group(0, bind)
            p.dispatch_workgroups(*_groups(n, self._max_groups))
        p.end()

    def pose(self, bone_transforms, means, quats, scales) -> None:
        """Upload ``bone_transforms`` [J, 4, 4], then skin and place into the given output buffers.
        Submits the work; reads nothing back."""
        self.set_bone_transforms(bone_transforms)
        enc = self.ctx.device.create_command_encoder(label="body.pose")
        self.encode(enc, means, quats, scales)
        self.ctx.submit(enc)

    # -- helpers ------------------------------------------------------------------------------------
    def output_buffers(self, label: str = "surfels") -> tuple:
        """New (means, quats, scales) buffers sized for the current surfels (tests and benchmarks;
        the renderer normally owns these)."""
        n = max(1, self.num_surfels)
        return (self.ctx.buffer(12 * n, f"{label}.means"), self.ctx.buffer(16 * n, f"{label}.quats"),
                self.ctx.buffer(8 * n, f"{label}.scales"))

    def read_posed_vertices(self) -> np.ndarray:
        """[V, 3] skinned vertices of the last pose (reads back; tests only)."""
        return self.ctx.read(self.posed_buf, np.float32, 3 * self.num_vertices).reshape(-1, 3)

    def read_surfels(self, means, quats, scales) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(means [N, 3], quats [N, 4], scales [N, 2]) from the output buffers (reads back; tests only)."""
        n = self.num_surfels
        return (self.ctx.read(means, np.float32, 3 * n).reshape(-1, 3),
                self.ctx.read(quats, np.float32, 4 * n).reshape(-1, 4),
                self.ctx.read(scales, np.float32, 2 * n).reshape(-1, 2))
