"""Cross-identity feature transfer (gma.edit): bit-identical copy on the same body shape, texture-only
transfer leaves everything else alone, fitted transfer across body shapes, refusal without shared
decoders."""

from __future__ import annotations

import pytest
import torch
from edit_helpers import fitted_avatar

from gma.avatar import Avatar, AvatarConfig
from gma.edit import EditError, Editor, Selection

OTHER_SHAPE = (0.9, 0.3, 0.8, 0.9, 0.95, 0.4)  # Anny phenotype: a taller, heavier, older man


@pytest.fixture(scope="module")
def pair(anny_body):
    target = fitted_avatar(anny_body)
    donor = fitted_avatar(anny_body)
    with torch.no_grad():  # another person on the same body shape and decoders
        donor.model.f_tex.copy_(donor.model.f_tex.roll(101, 0))
        donor.model.f_geo.copy_(donor.model.f_geo.roll(57, 0) + 0.2)
    return target, donor


def test_same_shape_copy_is_bit_identical(pair, anny_body):
    target, donor = pair
    ed = Editor(target, anny_body)
    before = target.decode()
    sel = Selection.from_regions(anny_body, "legs")
    change = ed.transfer(donor, sel, "both")
    try:
        assert change.info["mode"] == "copy" and change.mesh
        nk = target.config.fine_per_face
        rows = sel.mask().repeat_interleave(nk)
        mine, theirs = target.decode(), donor.decode()
        for a, b in ((mine.colors, theirs.colors), (mine.binding.uv, theirs.binding.uv),
                     (mine.binding.offset, theirs.binding.offset), (mine.binding.scale, theirs.binding.scale)):
            assert torch.equal(a[rows], b[rows])
            assert torch.equal(a[~rows], getattr_like(before, a, mine)[~rows])
        # Vertices whose faces all came from the donor carry the donor's mesh-layer offsets.
        faces = anny_body.faces
        outside = torch.zeros(anny_body.num_vertices, dtype=torch.bool)
        outside[faces[~sel.mask()].reshape(-1)] = True
        assert torch.equal(mine.vertex_offsets[~outside], theirs.vertex_offsets[~outside])
        assert not torch.equal(mine.vertex_offsets, before.vertex_offsets)
    finally:
        ed.undo()


def getattr_like(decoded, tensor, like):
    """The field of ``decoded`` that ``tensor`` is in ``like`` (so one loop compares every field)."""
    for name in ("colors",):
        if tensor is getattr(like, name):
            return getattr(decoded, name)
    for name in ("uv", "offset", "scale"):
        if tensor is getattr(like.binding, name):
            return getattr(decoded.binding, name)
    raise KeyError


def test_texture_transfer_leaves_geometry(pair, anny_body):
    target, donor = pair
    ed = Editor(target, anny_body)
    before = target.decode()
    geo = target.model.f_geo.detach().clone()
    sel = Selection.from_regions(anny_body, "torso")
    ed.transfer(donor, sel, "tex")
    try:
        after = target.decode()
        rows = sel.mask().repeat_interleave(target.config.fine_per_face)
        assert torch.equal(target.model.f_geo, geo) and torch.equal(after.vertex_offsets, before.vertex_offsets)
        assert torch.equal(after.binding.uv, before.binding.uv)
        assert torch.equal(after.binding.offset, before.binding.offset)
        assert torch.equal(after.colors[~rows], before.colors[~rows])
        assert torch.equal(after.colors[rows], donor.decode().colors[rows])
    finally:
        ed.undo()


def test_transfer_across_body_shapes(anny_body):
    """Same decoders, two shapes: the same feature decodes differently because the positional encoding
    comes from each avatar's own rest vertices; the fitted transfer brings the per-face mean colour error
    against the donor to <= 0.03 (and is far better than copying the rows)."""
    donor = fitted_avatar(anny_body)
    target = Avatar.create(donor.config, anny_body, torch.tensor(OTHER_SHAPE))
    target.model.load_state_dict(donor.model.state_dict())  # shared decoders (features overwritten below)
    with torch.no_grad():
        target.model.f_tex.copy_(target.model.f_tex.roll(3, 0))
    assert not torch.equal(target.model.pe, donor.model.pe)
    sel = Selection.from_regions(anny_body, "torso", "legs")
    nk = donor.config.fine_per_face
    want = donor.decode().colors.reshape(-1, nk, 3)[sel.faces].mean(1)

    errors = {}
    for mode in ("copy", "fit"):
        ed = Editor(target, anny_body)
        change = ed.transfer(donor, sel, "tex", mode=mode)
        got = ed.decoded.colors.reshape(-1, nk, 3)[change.faces].mean(1)
        errors[mode] = float((got - want).abs().mean())
        ed.undo()
    assert errors["fit"] <= 0.03 and errors["fit"] < errors["copy"], errors


def test_refuses_other_decoders(pair, anny_body):
    target, _ = pair
    other = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=2, hidden=64), anny_body)
    ed = Editor(target, anny_body)
    with pytest.raises(EditError, match=r"from b\.gma to a\.gma.*feature_dim 8 vs 16.*gma fit --decoders"):
        ed.transfer(other, Selection.from_regions(anny_body, "torso"), donor_name="b.gma", target_name="a.gma")
    same_size = fitted_avatar(anny_body, seed=5)  # same config, other decoder weights
    with pytest.raises(EditError, match="decoder weights"):
        ed.transfer(same_size, Selection.from_regions(anny_body, "torso"))
    with pytest.raises(EditError, match="empty"):
        ed.transfer(pair[1], Selection.from_ids([], anny_body.num_faces))
    assert not target.history
