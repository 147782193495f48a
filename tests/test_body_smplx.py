"""The SMPL-X backend on a tiny SMPL-X-format model file the test writes itself (same keys, array
conventions and joint count as the real SMPLX_*.npz; a 12-ring cylinder "body" instead of 10475
vertices), so smplx's loader and our skinning really run."""

from __future__ import annotations

import numpy as np
import pytest
import torch

smplx = pytest.importorskip("smplx")

from gma.body.smplx_body import NUM_JOINTS, SmplxBody  # noqa: E402

RINGS, SEGMENTS = 12, 10


def write_fake_smplx(path, seed: int = 0) -> None:
    """A cylinder of RINGS × SEGMENTS vertices along +Y with SMPL-X's 55-joint tree and array shapes."""
    rng = np.random.default_rng(seed)
    ang = np.linspace(0, 2 * np.pi, SEGMENTS, endpoint=False)
    ys = np.linspace(-0.9, 0.8, RINGS)
    v = np.stack([np.stack([0.15 * np.cos(ang), np.full(SEGMENTS, y), 0.15 * np.sin(ang)], 1) for y in ys])
    v = v.reshape(-1, 3)
    nv = len(v)
    faces = []
    for r in range(RINGS - 1):
        for s in range(SEGMENTS):
            a, b = r * SEGMENTS + s, r * SEGMENTS + (s + 1) % SEGMENTS
            faces += [[a, b + SEGMENTS, b], [a, a + SEGMENTS, b + SEGMENTS]]
    faces = np.asarray(faces, np.uint32)
    # Real SMPL-X parents (kintree_table row 0, root stored as uint32 max like the official files).
    parents = [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15,
               20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,
               21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53]
    kintree = np.stack([np.asarray(parents, np.int64) % 2**32, np.arange(NUM_JOINTS)]).astype(np.uint32)
    # Each joint regressed from 3 vertices of a ring (rows sum to 1, like the real regressor).
    jreg = np.zeros((NUM_JOINTS, nv))
    for j in range(NUM_JOINTS):
        jreg[j, rng.choice(nv, 3, replace=False)] = 1 / 3
    # Up to 4 influences per vertex, normalised.
    weights = np.zeros((nv, NUM_JOINTS))
    for i in range(nv):
        js = rng.choice(NUM_JOINTS, 4, replace=False)
        weights[i, js] = rng.random(4) + 0.1
    weights /= weights.sum(1, keepdims=True)
    np.savez(
        path,
        v_template=v, f=faces,
        shapedirs=rng.normal(0, 0.01, (nv, 3, 400)),  # 300 shape + 100 expression, as in SMPL-X 2020
        posedirs=rng.normal(0, 0.005, (nv, 3, (NUM_JOINTS - 1) * 9)),
        J_regressor=jreg, weights=weights, kintree_table=kintree,
        hands_componentsl=np.eye(45), hands_componentsr=np.eye(45),
        hands_meanl=rng.normal(0, 0.1, 45), hands_meanr=rng.normal(0, 0.1, 45),
        lmk_faces_idx=np.arange(51) % len(faces), lmk_bary_coords=np.full((51, 3), 1 / 3),
    )


@pytest.fixture(scope="module")
def smplx_dir(tmp_path_factory):
    d = tmp_path_factory.mktemp("smplx")
    write_fake_smplx(d / "SMPLX_NEUTRAL.npz")
    return d


@pytest.fixture(scope="module")
def body(smplx_dir):
    return SmplxBody.load(smplx_dir)


def random_params(body, seed=0, batch=()):
    g = torch.Generator().manual_seed(seed)
    return {
        "shape": torch.randn(10, generator=g),
        "expression": torch.randn(10, generator=g),
        "pose": torch.randn(*batch, NUM_JOINTS, 3, generator=g) * 0.3,
        "transl": torch.tensor([0.1, 0.2, -0.3]),
    }


def reference_vertices(body, p):
    """smplx's own lbs() on the same inputs (what SMPLX.forward computes for the vertices)."""
    from smplx.lbs import lbs

    m = body.smplx_model
    full = p["pose"].reshape(-1, NUM_JOINTS * 3) + m.pose_mean
    coeffs = torch.cat([p["shape"], p["expression"]])[None].expand(full.shape[0], -1)
    verts, _ = lbs(coeffs, full, m.v_template, torch.cat([m.shapedirs, m.expr_dirs], -1), m.posedirs,
                   m.J_regressor, m.parents, m.lbs_weights)
    return verts + p["transl"]


def test_loads_through_smplx(body):
    assert body.name == "smplx" and body.up_axis == "y"
    assert body.num_vertices == RINGS * SEGMENTS and body.num_bones == NUM_JOINTS
    assert body.num_faces == (RINGS - 1) * SEGMENTS * 2
    assert body.skin_indices.shape[1] == 4  # dense [V, 55] weights → 4 influences, nothing lost
    assert body.bone_parents[0] == -1 and body.bone_names[15] == "head"
    assert set(body.param_spaces) == {"shape", "expression", "pose", "transl"}


@pytest.mark.parametrize("seed", [0, 1])
def test_pose_matches_smplx_lbs(body, seed):
    p = random_params(body, seed)
    out = body.pose(p)
    torch.testing.assert_close(out.vertices, reference_vertices(body, p)[0], atol=1e-5, rtol=1e-5)


def test_batched_pose_and_gradients(body):
    p = random_params(body, 2, batch=(3,))
    p["pose"].requires_grad_(True)
    p["shape"].requires_grad_(True)
    out = body.pose(p)
    assert out.vertices.shape == (3, body.num_vertices, 3)
    torch.testing.assert_close(out.vertices.detach(), reference_vertices(body, p).detach(), atol=1e-5,
                               rtol=1e-5)
    out.vertices.sum().backward()
    assert p["pose"].grad.abs().sum() > 0 and p["shape"].grad.abs().sum() > 0


def test_without_correctives_rest_is_pose_independent(smplx_dir):
    b = SmplxBody.load(smplx_dir, pose_correctives=False)
    p = random_params(b, 3)
    r0 = b.rest_vertices(p)
    p["pose"] = p["pose"] * 2
    torch.testing.assert_close(b.rest_vertices(p), r0)


def test_gpu_skinning_of_smplx_rest(body, gpu):
    """The WGSL skinning reproduces smplx's vertices from (rest vertices, bone transforms)."""
    from gma.body.gpu_posing import GpuPoser
    from gma.body.placement import uniform_surfels

    p = random_params(body, 4)
    out = body.pose(p)
    poser = GpuPoser(gpu, body.faces, body.skin_indices, body.skin_weights)
    poser.set_rest_vertices(out.rest_vertices)
    poser.set_surfels(uniform_surfels(body.num_faces, 2))
    poser.pose(out.bone_transforms, *poser.output_buffers())
    np.testing.assert_allclose(poser.read_posed_vertices(), reference_vertices(body, p)[0].numpy(), atol=1e-5)


def test_missing_directory_says_where_to_get_files(monkeypatch, tmp_path):
    monkeypatch.delenv("GMA_SMPLX_DIR", raising=False)
    with pytest.raises(FileNotFoundError, match="smpl-x.is.tue.mpg.de"):
        SmplxBody.load(None)
    with pytest.raises(FileNotFoundError, match="SMPLX_NEUTRAL.npz"):
        SmplxBody.load(tmp_path)


def test_env_var_is_used(monkeypatch, smplx_dir):
    from gma.body import load_body

    monkeypatch.setenv("GMA_SMPLX_DIR", str(smplx_dir))
    assert load_body("smplx").num_bones == NUM_JOINTS


@pytest.mark.parametrize(
    "mutate,message",
    [
        (lambda d: d.pop("posedirs"), "array 'posedirs' is missing"),
        (lambda d: d.update(kintree_table=np.zeros((2, 24), np.uint32)),
         r"'kintree_table' has shape \[2, 24\]"),
        (lambda d: d.update(weights=np.zeros((5, 55))), "'weights' has 5 vertices"),
    ],
)
def test_wrong_file_is_a_clear_error(tmp_path, mutate, message):
    write_fake_smplx(tmp_path / "good.npz")
    data = dict(np.load(tmp_path / "good.npz"))
    mutate(data)
    np.savez(tmp_path / "SMPLX_NEUTRAL.npz", **data)
    with pytest.raises(ValueError, match=message):
        SmplxBody.load(tmp_path)


def test_not_an_npz(tmp_path):
    (tmp_path / "SMPLX_NEUTRAL.npz").write_text("hello")
    with pytest.raises(ValueError, match="not a readable SMPL-X .npz"):
        SmplxBody.load(tmp_path)
