"""Surfel placement on a posed mesh, in torch: the reference for ``shaders/wgsl/body/place.wgsl`` and the
path training differentiates through.

A surfel is bound to a face by (face id, barycentric u, v, normal offset d) and carries an in-face scale
[2] and an in-face rotation quaternion (w, x, y, z) relative to the face frame. On the posed mesh
(the paper's "Gaussian embed on Mesh"):

    mean  = u·V1 + v·V2 + (1 − u − v)·V3 + d·N_f           (V1..V3 the face's corners, N_f its unit normal)
    quat  = q_f ⊗ q_local                                   (q_f the face frame (t, n × t, n), t along V1→V2)
    scale = s_local · sqrt(area_f)

The face size factor is sqrt(area): it keeps a surfel's footprint a fixed fraction of its face, so
surfels stretch and shrink with the skin under posing and morphing, and ``s_local ≈ 0.5`` covers a face
of any size. ``d`` is in metres (not relative to the face size) so a garment layer keeps its thickness
on small and large faces alike.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.body.geometry import EPS, frame_from, safe_normalize

__all__ = [
    "SURFEL_LOCAL_DTYPE",
    "SurfelBinding",
    "pack_surfel_local",
    "place_surfels",
    "quat_multiply",
    "rotmat_to_quat",
    "uniform_surfels",
]

# Layout of ``SurfelLocal`` in shaders/wgsl/common/body_types.wgsl (48 bytes, 16-byte aligned).
SURFEL_LOCAL_DTYPE = np.dtype(
    [("face", "<u4"), ("u", "<f4"), ("v", "<f4"), ("d", "<f4"), ("quat", "<f4", 4), ("scale", "<f4", 2),
     ("_pad", "<f4", 2)]
)


@dataclass
class SurfelBinding:
    """Per-surfel binding to the mesh. N surfels.

    face_id: [N] int64 face index; uv: [N, 2] barycentric weights of V1, V2 (V3 gets 1 − u − v);
    offset: [N] normal offset d (m); scale: [N, 2] in-face scale (multiplied by sqrt(face area));
    quat: [N, 4] in-face rotation (w, x, y, z), need not be normalised.
    """

    face_id: torch.Tensor
    uv: torch.Tensor
    offset: torch.Tensor
    scale: torch.Tensor
    quat: torch.Tensor

    def __len__(self) -> int:
        return int(self.face_id.shape[0])

    def select(self, rows: torch.Tensor) -> SurfelBinding:
        """The surfels ``rows`` (indices or a bool mask [N]) as a binding of their own."""
        return SurfelBinding(self.face_id[rows], self.uv[rows], self.offset[rows], self.scale[rows], self.quat[rows])

    def validate(self, num_faces: int) -> None:
        n = len(self)
        shapes = {"face_id": (n,), "uv": (n, 2), "offset": (n,), "scale": (n, 2), "quat": (n, 4)}
        for name, want in shapes.items():
            got = tuple(getattr(self, name).shape)
            if got != want:
                raise ValueError(f"SurfelBinding.{name} must have shape {list(want)}, got {list(got)}")
        if n and (int(self.face_id.min()) < 0 or int(self.face_id.max()) >= num_faces):
            raise ValueError(f"SurfelBinding.face_id out of range [0, {num_faces})")


def uniform_surfels(num_faces: int, per_face: int, scale: float = 0.5, seed: int = 0) -> SurfelBinding:
    """``per_face`` surfels on every face at stratified-random barycentric positions, identity in-face
    rotation, ``scale`` in-face scale and zero offset — the initial fine layer of stage 2."""
    g = torch.Generator().manual_seed(seed)
    n = num_faces * per_face
    r1, r2 = torch.rand(n, generator=g), torch.rand(n, generator=g)
    # Uniform on the triangle: fold the unit square along its diagonal.
    fold = r1 + r2 > 1
    u = torch.where(fold, 1 - r1, r1)
    v = torch.where(fold, 1 - r2, r2)
    quat = torch.zeros(n, 4)
    quat[:, 0] = 1
    return SurfelBinding(
        face_id=torch.arange(num_faces).repeat_interleave(per_face),
        uv=torch.stack([u, v], 1),
        offset=torch.zeros(n),
        scale=torch.full((n, 2), float(scale)),
        quat=quat,
    )


def pack_surfel_local(b: SurfelBinding) -> np.ndarray:
    """The binding as a ``SURFEL_LOCAL_DTYPE`` array for upload to the GPU."""
    out = np.zeros(len(b), SURFEL_LOCAL_DTYPE)
    out["face"] = b.face_id.detach().cpu().numpy().astype(np.uint32)
    uv = b.uv.detach().cpu().float().numpy()
    out["u"], out["v"] = uv[:, 0], uv[:, 1]
    out["d"] = b.offset.detach().cpu().float().numpy()
    out["quat"] = b.quat.detach().cpu().float().numpy()
    out["scale"] = b.scale.detach().cpu().float().numpy()
    return out


def quat_multiply(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """Hamilton product a ⊗ b of (w, x, y, z) quaternions [..., 4]."""
    aw, ax, ay, az = a.unbind(-1)
    bw, bx, by, bz = b.unbind(-1)
    return torch.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        -1,
    )


def rotmat_to_quat(m: torch.Tensor) -> torch.Tensor:
    """Rotation matrices [..., 3, 3] → unit quaternions (w, x, y, z) [..., 4], Shepperd's method: take
    the largest of 4w², 4x², 4y², 4z² as the pivot so the square root never nears zero. The WGSL
    kernel uses the same branches, so both return the same sign."""
    # The nine entries in one unbind: its backward is one stack, where nine m[..., i, j] reads each wrote
    # their gradient into a zero-filled copy of m.
    m00, m01, m02, m10, m11, m12, m20, m21, m22 = m.flatten(-2).unbind(-1)
    trace = m00 + m11 + m22
    cands = torch.stack([trace, m00, m11, m22], -1)
    pivot = cands.argmax(-1)
    # Each candidate solution, computed for every matrix; the pivot picks one (branch-free for autograd).
    def sq(x):
        return torch.sqrt((1.0 + x).clamp_min(EPS)) * 2.0  # = 4·(pivot component)

    dx, dy, dz = m21 - m12, m02 - m20, m10 - m01  # antisymmetric part: 4w·(x, y, z)
    sxy, sxz, syz = m01 + m10, m02 + m20, m12 + m21  # symmetric part: 4xy, 4xz, 4yz
    s0 = sq(trace)
    q0 = torch.stack([0.25 * s0, dx / s0, dy / s0, dz / s0], -1)
    s1 = sq(m00 - m11 - m22)
    q1 = torch.stack([dx / s1, 0.25 * s1, sxy / s1, sxz / s1], -1)
    s2 = sq(m11 - m00 - m22)
    q2 = torch.stack([dy / s2, sxy / s2, 0.25 * s2, syz / s2], -1)
    s3 = sq(m22 - m00 - m11)
    q3 = torch.stack([dz / s3, sxz / s3, syz / s3, 0.25 * s3], -1)
    allq = torch.stack([q0, q1, q2, q3], -2)  # [..., 4, 4]
    return torch.gather(allq, -2, pivot[..., None, None].expand(*pivot.shape, 1, 4)).squeeze(-2)


def place_surfels(
    vertices: torch.Tensor,  # [V, 3] posed (morphed) mesh
    faces: torch.Tensor,  # [F, 3]
    binding: SurfelBinding,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """World-space (means [N, 3], quats [N, 4] (w, x, y, z), scales [N, 2]) of the bound surfels on the
    posed mesh, in the renderer's input conventions. Differentiable w.r.t. ``vertices`` and every
    float field of ``binding``."""
    fid = binding.face_id
    # What belongs to a face (normal, frame and its quaternion, area) is computed once for each face the
    # binding uses and gathered per surfel: a face carries N_k surfels (2-4), and computing it per surfel
    # made this function and its backward most of the torch time of a training or pose-fitting step.
    # The values are the same bit for bit; gradients sum the surfels of a face in another order.
    used = torch.zeros(faces.shape[0], dtype=torch.bool, device=fid.device)
    used[fid] = True
    face_rows = used.nonzero().squeeze(1)  # the faces some surfel sits on
    slot = (torch.cumsum(used, 0) - 1)[fid]  # each surfel's row in face_rows
    a, b, c = vertices[faces[face_rows]].unbind(1)  # [F', 3] each: the corners V1, V2, V3
    cross = torch.linalg.cross(b - a, c - a, dim=-1)
    normal = safe_normalize(cross)
    face_quat = rotmat_to_quat(frame_from(b - a, normal))
    area = 0.5 * cross.norm(dim=-1, keepdim=True)
    face_size = torch.sqrt(area.clamp_min(0.0) + EPS)
    # One gather of everything per surfel (one scatter in the backward instead of six).
    a, b, c, normal, face_quat, face_size = torch.cat([a, b, c, normal, face_quat, face_size], -1)[slot].split(
        [3, 3, 3, 3, 4, 1], -1)
    u, v = binding.uv[:, :1], binding.uv[:, 1:]
    means = u * a + v * b + (1 - u - v) * c + binding.offset[:, None] * normal
    quats = quat_multiply(face_quat, binding.quat)
    scales = binding.scale * face_size
    return means, quats, scales
