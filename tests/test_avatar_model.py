"""The avatar representation: decoding shapes and ranges, the .gma file round trip and bad files,
local re-decoding after an edit, and the viewer adapter."""

from __future__ import annotations

import json

import pytest
import torch

from gma.avatar import Avatar, AvatarConfig, AvatarFileError, pose_surfels

SMALL = dict(feature_dim=8, fine_per_face=2)


@pytest.fixture(scope="module")
def avatar(anny_body):
    return Avatar.create(AvatarConfig(**SMALL), anny_body, seed=3)


def test_decode_layers(avatar, anny_body):
    nf = anny_body.num_faces
    fine = avatar.decode("fine")
    assert len(fine.binding) == 2 * nf and fine.colors.shape == (2 * nf, 3)
    uv = fine.binding.uv
    assert (uv >= 0).all() and (uv.sum(1) <= 1 + 1e-6).all()  # inside the triangle
    assert fine.binding.offset.abs().max() <= avatar.config.fine_offset_max
    assert (fine.binding.scale > 0).all() and ((fine.colors >= 0) & (fine.colors <= 1)).all()
    coarse = avatar.decode("coarse")
    assert len(coarse.binding) == nf
    assert torch.allclose(coarse.colors, fine.colors.reshape(nf, 2, 3).mean(1))  # stage-1 colour = mean
    assert fine.vertex_offsets.shape == (anny_body.num_vertices, 3)


def test_mesh_layer_moves_along_normals(avatar, anny_body):
    """The morph is a scalar per vertex along the canonical vertex normal, bounded by offset_max."""
    m = avatar.model
    with torch.no_grad():
        m.F_coarse[2].bias.fill_(10.0)
        off = m.vertex_offsets()
        m.F_coarse[2].bias.zero_()
    assert torch.allclose(off, avatar.config.offset_max * torch.tanh(torch.tensor(10.0)) * m.vertex_normals,
                          atol=1e-5)


def test_direct_binding_has_no_mesh_layer(anny_body):
    """The direct ablation binds free surfels to the body's own faces: no morph, and a normal offset that
    reaches as far as the mesh layer and a fine surfel together."""
    av = Avatar.create(AvatarConfig(**SMALL, representation="direct"), anny_body)
    m = av.model
    assert m.param_groups()["geo_coarse"] == [] and not hasattr(m, "f_geo")
    with torch.no_grad():
        m.fine_raw[..., 3] = 10.0
    dec = av.decode()
    assert torch.equal(dec.vertex_offsets, torch.zeros_like(dec.vertex_offsets))
    reach = av.config.offset_max + av.config.fine_offset_max
    expected = reach * float(torch.tanh(torch.tensor(10.0)))
    assert torch.allclose(dec.binding.offset, torch.full_like(dec.binding.offset, expected))


def test_pose_is_differentiable(avatar, anny_body):
    dec = avatar.model.decode("fine")
    params = anny_body.canonical_params(avatar.shape)
    posed = pose_surfels(dec, anny_body.faces, anny_body.skin_indices, anny_body.skin_weights,
                         avatar.rest_vertices, anny_body.bone_transforms(params))
    (posed["means"].sum() + posed["scales"].sum() + posed["colors"].sum()).backward()
    assert avatar.model.f_geo.grad.abs().sum() > 0 and avatar.model.f_tex.grad.abs().sum() > 0
    avatar.model.zero_grad()


def test_file_round_trip(avatar, anny_body, tmp_path):
    avatar.history.append({"op": "paint", "faces": 3})
    path = avatar.save(tmp_path / "a.gma")
    back = Avatar.load(path, anny_body)
    assert back.config == avatar.config and back.history == avatar.history
    a, b = avatar.decode(), back.decode()
    assert torch.equal(a.colors, b.colors) and torch.equal(a.binding.uv, b.binding.uv)
    assert torch.equal(a.vertex_offsets, b.vertex_offsets) and torch.equal(back.shape, avatar.shape)
    assert not list(tmp_path.glob(".*tmp"))  # the atomic write left no temporary file


def test_bad_files(avatar, anny_body, tmp_path):
    from safetensors.torch import save_file

    good = avatar.save(tmp_path / "good.gma").read_bytes()
    (tmp_path / "trunc.gma").write_bytes(good[: len(good) // 2])
    (tmp_path / "text.gma").write_text("hello")
    save_file({"x": torch.zeros(2)}, str(tmp_path / "plain.gma"))
    for name in ("trunc.gma", "text.gma", "plain.gma"):
        with pytest.raises(AvatarFileError, match=name):
            Avatar.load(tmp_path / name, anny_body)
    # A newer format version is refused with a clear message.
    from safetensors.torch import load, save

    tensors = load(good)
    from safetensors import safe_open

    with safe_open(str(tmp_path / "good.gma"), "pt") as f:
        meta = dict(f.metadata())
    meta["version"] = "99"
    (tmp_path / "future.gma").write_bytes(save(tensors, metadata=meta))
    with pytest.raises(AvatarFileError, match="future.gma.*version 99 is newer"):
        Avatar.load(tmp_path / "future.gma", anny_body)
    with pytest.raises(FileNotFoundError, match="missing.gma"):
        Avatar.load(tmp_path / "missing.gma", anny_body)
    meta["version"], meta["config"] = "1", json.dumps({"nonsense": 1})
    (tmp_path / "cfg.gma").write_bytes(save(tensors, metadata=meta))
    with pytest.raises(AvatarFileError, match="cfg.gma"):
        Avatar.load(tmp_path / "cfg.gma", anny_body)


def test_redecode_only_touched_faces(anny_body):
    av = Avatar.create(AvatarConfig(**SMALL), anny_body, seed=1)
    dec = av.decode()
    before = dec.colors.clone()
    faces = torch.tensor([5, 100, 2000])
    with torch.no_grad():
        av.model.f_tex[faces] += 3.0  # an "edit" of the texture features of three faces
    rows = av.model.redecode_faces(dec, faces)
    assert rows.tolist() == [10, 11, 200, 201, 4000, 4001]
    changed = (dec.colors != before).any(1).nonzero().flatten()
    assert set(changed.tolist()) <= set(rows.tolist()) and len(changed) > 0
    assert torch.allclose(dec.colors, av.decode().colors)  # same as a full decode


def test_view_adapter(anny_body, gpu, tmp_path):
    """``gma view avatar.gma`` opens through gma.view.load_source -> gma.view.source.avatar_source."""
    from gma.view.source import load_source

    av = Avatar.create(AvatarConfig(**SMALL), anny_body)
    path = av.save(tmp_path / "v.gma")
    src = load_source(gpu, str(path))
    assert src.surfels.count == 2 * anny_body.num_faces and src.mesh is not None
