"""The Anny backend against anny's own plain-torch posing, plus labels, regions and parameter spaces."""

from __future__ import annotations

import math

import pytest
import torch

from gma.body.geometry import face_areas, face_centers, vertex_normals


def random_pose(body, seed=0, scale=0.3):
    """Small random rotations on every bone plus a root translation ([J, 4, 4] local-ref deltas)."""
    g = torch.Generator().manual_seed(seed)
    aa = torch.randn(body.num_bones, 3, generator=g) * scale
    from gma.body.motions import axis_angle_to_matrix

    pose = torch.eye(4).repeat(body.num_bones, 1, 1)
    pose[:, :3, :3] = axis_angle_to_matrix(aa)
    pose[0, :3, 3] = torch.tensor([0.1, -0.2, 0.3])
    return pose


def test_default_topology_and_rig(anny_body):
    b = anny_body
    assert b.name == "anny" and b.up_axis == "z"
    assert b.num_faces == 27420 and b.num_bones == 104
    assert b.faces.shape == (27420, 3) and b.face_uvs.shape == (27420, 3, 2)
    assert b.skin_indices.shape == b.skin_weights.shape == (b.num_vertices, b.skin_indices.shape[1])
    torch.testing.assert_close(b.skin_weights.sum(1), torch.ones(b.num_vertices), atol=1e-4, rtol=0)
    assert float(b.face_uvs.min()) >= 0 and float(b.face_uvs.max()) <= 1
    assert b.param_spaces["shape"].labels == ("gender", "age", "muscle", "weight", "height", "proportions")
    assert len(b.param_spaces["expression"].labels) == 52
    assert "jawOpen" in b.param_spaces["expression"].labels
    assert b.bone_parents[0] == -1 and all(0 <= p < i for i, p in enumerate(b.bone_parents) if i)


def test_cached_creation_returns_same_object(anny_body):
    from gma.body import load_body

    assert load_body("anny") is anny_body


@pytest.mark.parametrize("seed,phenotype", [(0, 0.5), (1, 0.2), (2, 0.9)])
def test_pose_matches_anny(anny_body, seed, phenotype):
    b = anny_body
    pose = random_pose(b, seed)
    shape = torch.full((6,), phenotype)
    expr = torch.zeros(52)
    expr[b.param_spaces["expression"].labels.index("jawOpen")] = 0.7
    out = b.pose({"pose": pose, "shape": shape, "expression": expr})
    ref = b.anny_model(pose[None], phenotype_kwargs=shape[None], facial_actions=expr[None])
    # Same float32 arithmetic except for the LBS order of operations (sparse gather vs dense einsum).
    torch.testing.assert_close(out.vertices, ref["vertices"][0], atol=2e-5, rtol=0)


def test_batched_pose(anny_body):
    b = anny_body
    poses = torch.stack([random_pose(b, 3), random_pose(b, 4)])
    out = b.pose({"pose": poses})
    assert out.vertices.shape == (2, b.num_vertices, 3) and out.bone_transforms.shape == (2, 104, 4, 4)
    single = b.pose({"pose": poses[1]})
    torch.testing.assert_close(out.vertices[1], single.vertices, atol=1e-5, rtol=0)


def test_canonical_pose_is_upright_a_pose(anny_body):
    b = anny_body
    v = b.pose(b.canonical_params()).vertices
    height = float(v[:, 2].max() - v[:, 2].min())
    assert 1.4 < height < 2.0  # metres, Z-up
    # Hands below the shoulders and away from the hips: an A-pose.
    c = face_centers(v, b.faces)
    hands = c[b.regions["hands"]]
    assert float(hands[:, 2].mean()) < float(c[b.regions["head"]][:, 2].min())
    assert float(hands[:, 0].abs().mean()) > 0.3


def test_shape_and_expression_move_the_right_vertices(anny_body):
    b = anny_body
    base = b.rest_vertices({})
    tall = b.rest_vertices({"shape": torch.tensor([0.5, 0.5, 0.5, 0.5, 1.0, 0.5])})
    assert float(tall[:, 2].max() - tall[:, 2].min()) > float(base[:, 2].max() - base[:, 2].min()) + 0.05
    expr = torch.zeros(52)
    expr[b.param_spaces["expression"].labels.index("jawOpen")] = 1.0
    moved = (b.rest_vertices({"expression": expr}) - base).norm(dim=1) > 1e-4
    # Only the face and chin move: everything moved lies above the shoulders.
    shoulder_z = float(base[torch.unique(b.faces[b.regions["arms"]]), 2].max())
    assert moved.any() and float(base[moved, 2].min()) > shoulder_z - 0.05


def test_gradients_reach_shape_and_pose(anny_body):
    b = anny_body
    shape = torch.full((6,), 0.5, requires_grad=True)
    pose = random_pose(b, 5).requires_grad_(True)
    out = b.pose({"shape": shape, "pose": pose})
    out.vertices.square().sum().backward()
    assert shape.grad.abs().sum() > 0 and pose.grad.abs().sum() > 0


def test_labels_and_regions(anny_body):
    b = anny_body
    assert b.face_labels.shape == (b.num_faces,)
    assert {"head", "hand.L", "hand.R", "foot.L", "foot.R", "body"} <= set(b.face_label_names)
    base = ["head", "torso", "arms", "hands", "legs", "feet"]
    stacked = torch.stack([b.regions[r] for r in base])
    assert bool((stacked.sum(0) == 1).all()), "base regions must partition the faces"
    assert bool((b.regions["upper_body"] & b.regions["lower_body"]).sum() == 0)
    c = face_centers(b.rest_vertices({}), b.faces)
    z = {r: float(c[b.regions[r], 2].mean()) for r in base + ["upper_body", "lower_body"]}
    assert z["head"] > z["upper_body"] > z["lower_body"] > z["feet"]
    assert b.region_mask("hand.L").sum() > 0
    with pytest.raises(ValueError, match="unknown body region"):
        b.region_mask("tail")


def test_bad_params_are_clear_errors(anny_body):
    with pytest.raises(ValueError, match=r"'pose' must have shape \[\.\.\., 104, 4, 4\]"):
        anny_body.pose({"pose": torch.eye(4)})
    with pytest.raises(ValueError, match="unknown body parameters"):
        anny_body.pose({"betas": torch.zeros(10)})


def test_geometry_on_anny_mesh(anny_body):
    v = anny_body.rest_vertices({})
    a = face_areas(v, anny_body.faces)
    assert float(a.sum()) > 1.0 and int((a <= 0).sum()) < 10  # ~1.8 m² of skin incl. eyes and mouth
    n = vertex_normals(v, anny_body.faces)
    assert torch.isfinite(n).all()
    assert math.isclose(float(n.norm(dim=1).median()), 1.0, abs_tol=1e-5)


def test_expression_basis_is_linear(anny_body):
    b = anny_body
    basis = b.expression_basis()
    assert basis.shape == (52, b.num_vertices, 3)
    e = torch.rand(52, generator=torch.Generator().manual_seed(0)) * 0.5
    expect = b.rest_vertices({}) + torch.einsum("k,kvc->vc", e, basis)
    torch.testing.assert_close(b.rest_vertices({"expression": e}), expect, atol=1e-5, rtol=0)
    torch.testing.assert_close(b.bone_transforms({"expression": e}), b.bone_transforms({}), atol=1e-6, rtol=0)
