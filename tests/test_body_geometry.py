"""Mesh geometry, skinning and placement in torch (no model files, no GPU)."""

from __future__ import annotations

import math

import pytest
import torch

from gma.body import geometry as G
from gma.body.placement import SurfelBinding, place_surfels, quat_multiply, rotmat_to_quat, uniform_surfels
from gma.body.skinning import dense_to_sparse_weights, linear_blend_skinning


def tetra():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    f = torch.tensor([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward, counter-clockwise
    return v, f


def grid(n=4):
    """An n×n vertex grid in the z = 0 plane, 2(n-1)² faces, normals +z."""
    ys, xs = torch.meshgrid(torch.arange(n, dtype=torch.float32), torch.arange(n, dtype=torch.float32),
                            indexing="ij")
    v = torch.stack([xs.flatten(), ys.flatten(), torch.zeros(n * n)], 1)
    faces = []
    for r in range(n - 1):
        for c in range(n - 1):
            i = r * n + c
            faces += [[i, i + 1, i + n + 1], [i, i + n + 1, i + n]]
    return v, torch.tensor(faces)


def quat_to_rotmat(q):
    q = q / q.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack([
        1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
        2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
        2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1).reshape(*q.shape[:-1], 3, 3)


def test_face_quantities_on_tetrahedron():
    v, f = tetra()
    areas = G.face_areas(v, f)
    torch.testing.assert_close(areas[:3], torch.full((3,), 0.5))
    torch.testing.assert_close(areas[3], torch.tensor(math.sqrt(3) / 2))
    n = G.face_normals(v, f)
    c = G.face_centers(v, f)
    # Outward: the normal points away from the tetrahedron's centroid.
    assert bool(((c - v.mean(0)) * n).sum(-1).gt(0).all())
    frames = G.face_frames(v, f)
    torch.testing.assert_close(frames.transpose(-1, -2) @ frames, torch.eye(3).expand(4, 3, 3), atol=1e-6,
                               rtol=0)
    torch.testing.assert_close(torch.linalg.det(frames), torch.ones(4), atol=1e-6, rtol=0)
    torch.testing.assert_close(frames[..., 2], n)


def test_vertex_normals_and_morph():
    v, f = grid(5)
    vn = G.vertex_normals(v, f)
    torch.testing.assert_close(vn, torch.tensor([0.0, 0, 1]).expand_as(vn))
    moved = G.morph_vertices(v, f, torch.full((25,), 0.25))
    torch.testing.assert_close(moved[:, 2], torch.full((25,), 0.25))


def test_degenerate_face_is_finite():
    v = torch.tensor([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [0, 0, 0]])
    f = torch.tensor([[0, 1, 2], [0, 3, 1]])  # collinear, and one with a repeated point
    for out in (G.face_normals(v, f), G.face_frames(v, f), G.vertex_normals(v, f), G.face_areas(v, f)):
        assert torch.isfinite(out).all()
    assert G.face_areas(v, f).abs().max() == 0


def test_edges_adjacency_laplacians():
    v, f = tetra()
    assert G.mesh_edges(f).shape == (6, 2)
    torch.testing.assert_close(G.edge_lengths(v, f).sort().values,
                               torch.tensor([1.0, 1, 1, math.sqrt(2), math.sqrt(2), math.sqrt(2)]))
    assert G.face_adjacency(f).shape == (6, 2)  # every pair of tetrahedron faces shares an edge
    adj = G.vertex_adjacency(f, 4).to_dense()
    assert adj.sum() == 12 and adj.diagonal().sum() == 0
    lu = G.uniform_laplacian(f, 4).to_dense()
    torch.testing.assert_close(lu.sum(1), torch.zeros(4), atol=1e-6, rtol=0)
    # A planar grid: the cotangent Laplacian annihilates linear functions at interior vertices.
    gv, gf = grid(5)
    lc = G.cotangent_laplacian(gv, gf).to_dense()
    torch.testing.assert_close(lc, lc.T)
    interior = [6, 7, 8, 11, 12, 13, 16, 17, 18]
    torch.testing.assert_close((lc @ gv)[interior], torch.zeros(9, 3), atol=1e-5, rtol=0)
    assert torch.linalg.eigvalsh(lc).min() > -1e-5


def test_cotangent_laplacian_gradient_flows():
    v, f = tetra()
    v = v.clone().requires_grad_(True)
    (G.cotangent_laplacian(v, f).to_dense() @ v).square().sum().backward()
    assert torch.isfinite(v.grad).all() and v.grad.abs().sum() > 0


@pytest.mark.parametrize("batch", [(), (3,)])
def test_lbs_matches_dense_reference(batch):
    g = torch.Generator().manual_seed(1)
    nv, nj = 50, 7
    rest = torch.randn(*batch, nv, 3, generator=g)
    dense = torch.rand(nv, nj, generator=g) * (torch.rand(nv, nj, generator=g) > 0.5)
    dense[:, 0] += 1e-3
    dense = dense / dense.sum(1, keepdim=True)
    idx, w = dense_to_sparse_weights(dense)
    rot = torch.linalg.qr(torch.randn(*batch, nj, 3, 3, generator=g)).Q
    T = torch.eye(4).repeat(*batch, nj, 1, 1)
    T[..., :3, :3] = rot
    T[..., :3, 3] = torch.randn(*batch, nj, 3, generator=g)
    ref = torch.einsum("vj,...jab,...vb->...va", dense, T[..., :3, :3], rest) + dense @ T[..., :3, 3]
    torch.testing.assert_close(linear_blend_skinning(rest, idx, w, T), ref, atol=1e-5, rtol=1e-5)


def test_rotmat_to_quat_roundtrip_all_branches():
    g = torch.Generator().manual_seed(2)
    q = torch.randn(200, 4, generator=g)
    # Include rotations by ~π about each axis, which exercise the x, y and z pivots.
    q[:3] = torch.tensor([[0.01, 1, 0, 0], [0.01, 0, 1, 0], [0.01, 0, 0, 1]])
    m = quat_to_rotmat(q)
    torch.testing.assert_close(quat_to_rotmat(rotmat_to_quat(m)), m, atol=1e-5, rtol=0)
    torch.testing.assert_close(rotmat_to_quat(m).norm(dim=-1), torch.ones(200), atol=1e-5, rtol=0)


def test_place_surfels_on_grid():
    v, f = grid(3)
    b = uniform_surfels(f.shape[0], 4, scale=0.5)
    b.offset = torch.full((len(b),), 0.1)
    means, quats, scales = place_surfels(v, f, b)
    torch.testing.assert_close(means[:, 2], torch.full((len(b),), 0.1))
    rot = quat_to_rotmat(quats)
    torch.testing.assert_close(rot[:, :, 2], torch.tensor([0.0, 0, 1]).expand(len(b), 3), atol=1e-6, rtol=0)
    torch.testing.assert_close(scales, torch.full_like(scales, 0.5 * math.sqrt(0.5)))
    # Barycentric points stay inside their face's bounding box (unit cells of the grid).
    corners = v[f[b.face_id]]
    assert bool((means[:, :2] >= corners[..., :2].min(1).values - 1e-6).all())
    assert bool((means[:, :2] <= corners[..., :2].max(1).values + 1e-6).all())


def test_in_face_rotation_composes():
    v, f = grid(2)
    b = SurfelBinding(face_id=torch.tensor([0]), uv=torch.tensor([[0.3, 0.3]]), offset=torch.zeros(1),
                      scale=torch.ones(1, 2), quat=torch.tensor([[math.cos(0.4), 0, 0, math.sin(0.4)]]))
    _, q, _ = place_surfels(v, f, b)
    frame = G.face_frames(v, f[:1])
    expect = frame[0] @ quat_to_rotmat(b.quat)[0]
    torch.testing.assert_close(quat_to_rotmat(q)[0], expect, atol=1e-6, rtol=0)
    torch.testing.assert_close(quat_multiply(torch.tensor([1.0, 0, 0, 0]), q[0]), q[0])


def test_placement_is_differentiable():
    v, f = grid(3)
    v = (v + 0.05 * torch.randn_like(v)).requires_grad_(True)
    b = uniform_surfels(f.shape[0], 2)
    for t in (b.uv, b.offset, b.scale, b.quat):
        t.requires_grad_(True)
    means, quats, scales = place_surfels(v, f, b)
    (means.sum() + quats.sum() + scales.sum()).backward()
    for t in (v, b.uv, b.offset, b.scale, b.quat):
        assert t.grad is not None and torch.isfinite(t.grad).all()


def test_binding_validation():
    b = uniform_surfels(2, 1)
    with pytest.raises(ValueError, match="face_id out of range"):
        b.validate(1)
    b.uv = b.uv[:, :1]
    with pytest.raises(ValueError, match="uv must have shape"):
        b.validate(2)
