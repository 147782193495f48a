"""WGSL skinning + surfel placement against the torch reference (lavapipe, small meshes)."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gma.body.placement import SURFEL_LOCAL_DTYPE, SurfelBinding, place_surfels, uniform_surfels
from gma.body.skinning import linear_blend_skinning

pytestmark = pytest.mark.gpu

# float32 on both sides; the kernels sum the K weighted transformed points while torch blends the
# matrices first, so results differ by rounding only: a few ulps of the ~1 m coordinates.
ATOL = 2e-5


def random_rig(nv: int, nf: int, nj: int, k: int, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    rest = torch.randn(nv, 3, generator=g) * 0.5
    faces = torch.randint(0, max(nv, 1), (nf, 3), generator=g)
    idx = torch.randint(0, nj, (nv, k), generator=g)
    w = torch.rand(nv, k, generator=g)
    w[:, -1] = 0  # a padding slot, as in real rigs with fewer influences than K
    w = w / w.sum(1, keepdim=True).clamp_min(1e-6)
    q = torch.linalg.qr(torch.randn(nj, 3, 3, generator=g)).Q
    q = q * torch.linalg.det(q)[:, None, None]  # proper rotations
    T = torch.eye(4).repeat(nj, 1, 1)
    T[:, :3, :3] = q
    T[:, :3, 3] = torch.randn(nj, 3, generator=g)
    return rest, faces, idx, w, T


def random_binding(nf: int, n: int, seed: int = 0) -> SurfelBinding:
    """N surfels on random faces with random offsets, scales and (un-normalised) local rotations."""
    g = torch.Generator().manual_seed(seed)
    return SurfelBinding(
        face_id=torch.randint(0, nf, (n,), generator=g),
        uv=torch.rand(n, 2, generator=g) * 0.5,  # u + v ≤ 1: inside the face
        offset=torch.randn(n, generator=g) * 0.01,
        scale=torch.rand(n, 2, generator=g) + 0.1,
        quat=torch.randn(n, 4, generator=g),
    )


def quat_close(a: np.ndarray, b: np.ndarray, atol: float) -> None:
    """q and −q are the same rotation; the branch choice can flip sign only at exact pivot ties."""
    d = np.minimum(np.abs(a - b).max(-1), np.abs(a + b).max(-1))
    assert d.max(initial=0.0) <= atol, f"quaternion mismatch {d.max()}"


def test_surfel_local_layout_matches_wgsl(gpu):
    src = gpu.shaders.source("body/place.wgsl", {"WG": 256})
    assert "struct SurfelLocal" in src
    # face u32, u, v, d f32, quat vec4 (offset 16), scale vec2 (offset 32), pad vec2 → 48 bytes.
    assert SURFEL_LOCAL_DTYPE.itemsize == 48
    assert SURFEL_LOCAL_DTYPE.fields["quat"][1] == 16 and SURFEL_LOCAL_DTYPE.fields["scale"][1] == 32


@pytest.mark.parametrize(
    "nv,nf,nj,k,n",
    [
        (40, 60, 5, 4, 60),  # one surfel per face
        (300, 500, 13, 9, 257),  # not a multiple of the workgroup size
        (10, 8, 3, 1, 1),  # a single surfel, rigid (K = 1) skinning
        (10, 8, 3, 2, 0),  # no surfels: skinning still runs
    ],
)
def test_wgsl_matches_torch(gpu, nv, nf, nj, k, n):
    from gma.body.gpu_posing import GpuPoser

    rest, faces, idx, w, T = random_rig(nv, nf, nj, k)
    binding = random_binding(nf, n)
    poser = GpuPoser(gpu, faces, idx, w)
    poser.set_rest_vertices(rest)
    poser.set_surfels(binding)
    outs = poser.output_buffers()
    poser.pose(T, *outs)

    posed = linear_blend_skinning(rest, idx, w, T)
    np.testing.assert_allclose(poser.read_posed_vertices(), posed.numpy(), atol=ATOL, rtol=0)
    means, quats, scales = place_surfels(posed, faces, binding)
    gm, gq, gs = poser.read_surfels(*outs)
    assert gm.shape == (n, 3) and gq.shape == (n, 4) and gs.shape == (n, 2)
    np.testing.assert_allclose(gm, means.numpy(), atol=ATOL, rtol=0)
    np.testing.assert_allclose(gs, scales.numpy(), atol=ATOL, rtol=1e-4)
    # Quaternions: unit face frame times an un-normalised local quaternion (|q| up to ~3): relative
    # tolerance on top of the absolute one.
    quat_close(gq / np.linalg.norm(gq, axis=1, keepdims=True).clip(1e-9),
               (quats / quats.norm(dim=1, keepdim=True).clamp_min(1e-9)).numpy(), 1e-4)


def test_degenerate_faces_agree(gpu):
    """Zero-area faces: both paths give finite output (zero normal, identity-ish frame)."""
    from gma.body.gpu_posing import GpuPoser

    rest = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 1, 0]])
    faces = torch.tensor([[0, 1, 2], [0, 0, 0], [0, 1, 3]])
    idx = torch.zeros(4, 1, dtype=torch.long)
    w = torch.ones(4, 1)
    binding = uniform_surfels(3, 2)
    poser = GpuPoser(gpu, faces, idx, w)
    poser.set_rest_vertices(rest)
    poser.set_surfels(binding)
    outs = poser.output_buffers()
    poser.pose(torch.eye(4)[None], *outs)
    gm, gq, gs = poser.read_surfels(*outs)
    means, quats, scales = place_surfels(rest, faces, binding)
    assert np.isfinite(gm).all() and np.isfinite(gq).all() and np.isfinite(gs).all()
    np.testing.assert_allclose(gm, means.numpy(), atol=ATOL)
    np.testing.assert_allclose(gs, scales.numpy(), atol=ATOL)
    quat_close(gq, quats.numpy(), 1e-5)


def test_bad_inputs_are_clear_errors(gpu):
    from gma.body.gpu_posing import GpuPoser

    rest, faces, idx, w, T = random_rig(10, 8, 3, 2)
    poser = GpuPoser(gpu, faces, idx, w)
    with pytest.raises(RuntimeError, match="set_rest_vertices"):
        poser.encode(gpu.device.create_command_encoder(), *poser.output_buffers())
    with pytest.raises(ValueError, match=r"rest_vertices must be \[10, 3\]"):
        poser.set_rest_vertices(rest[:5])
    with pytest.raises(ValueError, match="bone_transforms"):
        poser.set_bone_transforms(T[:1])
    poser.set_rest_vertices(rest)
    poser.set_surfels(uniform_surfels(8, 2))
    small = poser.output_buffers()
    poser.set_surfels(uniform_surfels(8, 4))
    with pytest.raises(ValueError, match="means buffer holds"):
        poser.pose(T, *small)


def test_anny_walk_frame_wgsl_matches_torch(gpu, anny_body):
    """The default body, a walk frame, a morphed rest mesh, 2 surfels per face (~55k)."""
    from gma.body.geometry import morph_vertices
    from gma.body.gpu_posing import GpuPoser
    from gma.body.motions import motion

    b = anny_body
    frame = motion("walk", 8, b).params(3)
    offsets = 0.005 * torch.sin(torch.arange(b.num_vertices, dtype=torch.float32))  # a bumpy mesh layer
    rest = morph_vertices(b.rest_vertices(frame), b.faces, offsets)
    transforms = b.bone_transforms(frame)
    binding = random_binding(b.num_faces, 2 * b.num_faces, seed=7)
    poser = GpuPoser(gpu, b.faces, b.skin_indices, b.skin_weights)
    poser.set_rest_vertices(rest)
    poser.set_surfels(binding)
    outs = poser.output_buffers()
    poser.pose(transforms, *outs)

    posed = linear_blend_skinning(rest, b.skin_indices, b.skin_weights, transforms)
    np.testing.assert_allclose(poser.read_posed_vertices(), posed.numpy(), atol=ATOL, rtol=0)
    means, quats, scales = place_surfels(posed, b.faces, binding)
    gm, gq, gs = poser.read_surfels(*outs)
    # Anny's smallest faces (eyes, mouth interior) have edges of ~1 mm: their frames and sqrt(area) are
    # more sensitive to the ulp-level differences of the skinned vertices (measured worst quaternion
    # difference 2.5e-4), hence looser tolerances here than on the random meshes. A mean sits `offset`
    # along its face's normal, so it inherits that frame error times |offset| (seen: 2.17e-5 off on a
    # sliver face with a 0.8 mm edge and offset 0.021, on one machine, where ATOL alone allows 2e-5).
    mean_tol = ATOL + 1e-3 * binding.offset.abs().numpy()[:, None]
    worst = np.abs(gm - means.numpy()) - mean_tol
    where = np.unravel_index(worst.argmax(), worst.shape)
    assert worst.max() <= 0, f"surfel mean {where} off by {worst.max():.3g} beyond its tolerance"
    np.testing.assert_allclose(gs, scales.numpy(), atol=ATOL, rtol=1e-3)
    quat_close(gq / np.linalg.norm(gq, axis=1, keepdims=True),
               (quats / quats.norm(dim=1, keepdim=True)).numpy(), 1e-3)
