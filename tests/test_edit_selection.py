"""Selections (gma.edit): the face-ID render against its numpy twin, visible-only screen selections,
brush falloff, magic wand, grow/shrink, set algebra and the JSON file."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from edit_helpers import fitted_avatar

from gma.core.camera import Camera
from gma.edit import EditError, Editor, FaceIdRenderer, Selection, face_id_reference
from gma.edit.screen import faces_in_box


def _mesh():
    """Two overlapping quads at different depths plus a small fan: occlusion, shared edges, odd sizes."""
    v = np.array([[-0.5, -0.5, 0], [0.5, -0.5, 0], [0.5, 0.5, 0], [-0.5, 0.5, 0],          # far quad
                  [-0.2, -0.3, -0.3], [0.6, -0.3, -0.3], [0.6, 0.4, -0.3], [-0.2, 0.4, -0.3],  # near quad
                  [-0.45, 0.1, -0.1], [-0.3, 0.45, -0.1], [-0.1, 0.2, -0.1]], np.float32)
    f = np.array([[0, 1, 2], [0, 2, 3], [4, 5, 6], [4, 6, 7], [8, 9, 10]])
    return v, f


@pytest.mark.parametrize("size", [(37, 29), (64, 64)])
def test_face_id_render_matches_reference(gpu, size):
    v, f = _mesh()
    cam = Camera.look_at((0.1, -0.2, -2.0), (0, 0, 0), up=(0, -1, 0), fov_y_deg=40, width=size[0], height=size[1])
    got = FaceIdRenderer(gpu, f).render(v, cam)
    want = face_id_reference(v, f, cam)
    agree = got.ids == want.ids
    assert agree.mean() >= 0.97  # edges may round to either side (rasterisation tie rules)
    assert set(np.unique(got.ids)) == set(np.unique(want.ids)) == {-1, 0, 1, 2, 3, 4}
    both = agree & (want.ids >= 0)
    assert np.allclose(got.depth[both], want.depth[both], atol=1e-4)
    assert np.isinf(got.depth[got.ids < 0]).all()


@pytest.fixture(scope="module")
def editor(gpu, anny_body):
    return Editor(fitted_avatar(anny_body), anny_body, gpu)


def test_box_takes_only_visible_faces(editor):
    """From the avatar's left, the arm hides part of the torso: faces_in_box (front-facing only) takes
    those, Selection.box does not; everything it takes is drawn or at the drawn depth."""
    view = editor.named_view("left", 128, 128)
    box = (0, 0, 128, 128)
    sel = Selection.box(view, box)
    naive = faces_in_box(view.vertices, view.faces, view.camera, box)
    torso = editor.body.region_mask("torso").numpy()
    mask = sel.mask().numpy()
    assert (mask & ~naive).sum() == 0
    assert (naive & torso & ~mask).sum() > 100  # torso faces behind the arm
    drawn = np.zeros(editor.num_faces, bool)
    drawn[np.unique(view.ids.ids[view.ids.ids >= 0])] = True
    assert (drawn & naive & ~mask).sum() < 0.02 * drawn.sum()  # what is drawn is (almost all) taken


def test_brush_lasso_and_algebra(editor):
    view = editor.named_view("front", 128, 128)
    centre = view.px[editor.body.region_mask("torso").numpy() & view.visible].mean(0)
    brush = Selection.brush(view, centre, 12, falloff=0.5)
    w = brush.face_weights()
    d = np.linalg.norm(view.px[brush.faces.numpy()] - centre, axis=1)
    assert brush.soft and float(w.max()) == 1.0 and (w[torch.from_numpy(d < 6)] == 1).all()
    assert (w[torch.from_numpy(d > 11)] < 0.1).all()
    lasso = Selection.lasso(view, [(centre[0] - 10, centre[1] - 10), (centre[0] + 10, centre[1] - 10),
                                   (centre[0], centre[1] + 10)])
    assert 0 < len(lasso) < len(Selection.box(view, (0, 0, 128, 128)))
    u = brush.union(lasso)
    assert len(u) >= max(len(brush), len(lasso))
    s = u.subtract(Selection.from_mask(lasso.mask()))
    assert not bool((s.mask() & lasso.mask()).any())
    inv = lasso.invert()
    assert len(inv) == editor.num_faces - len(lasso) and not bool((inv.mask() & lasso.mask()).any())
    g = lasso.grow(editor.graph, 2)
    assert bool((g.mask() | lasso.mask()).equal(g.mask())) and len(g) > len(lasso)
    sh = g.shrink(editor.graph, 1)
    assert not bool((sh.mask() & ~g.mask()).any()) and len(sh) < len(g)
    with pytest.raises(EditError, match="empty"):
        Selection.from_ids([], editor.num_faces).require()


def test_wand_picks_the_shirt(editor):
    """The garment avatar's torso is a speckled blue shirt: the wand from a chest pixel takes (most of)
    the torso and next to nothing of the skin-coloured arms."""
    view = editor.named_view("front", 128, 128)
    torso = editor.body.region_mask("torso")
    centre = view.px[torso.numpy() & view.visible].mean(0)
    sel = editor.wand(view, *centre, tolerance=0.45)
    m = sel.mask()
    iou = float((m & torso).sum() / (m | torso).sum())
    assert iou > 0.7, iou
    arms = editor.body.region_mask("arms")
    assert float((m & arms).sum()) < 0.02 * float(arms.sum())  # a few speckles of the skin come close
    with pytest.raises(EditError, match="shows no face"):
        editor.wand(view, 0, 0)


def test_regions_and_file(editor, tmp_path):
    sel = Selection.from_regions(editor.body, "hands", "feet")
    assert len(sel) == int((editor.body.region_mask("hands") | editor.body.region_mask("feet")).sum())
    with pytest.raises(EditError, match="unknown body region"):
        Selection.from_regions(editor.body, "wings")
    soft = Selection.from_ids([5, 3, 9], editor.num_faces, [0.5, 1.0, 0.25])
    soft.save(tmp_path / "s.json", editor.body.name)
    back = Selection.load(tmp_path / "s.json", editor.body.name, editor.num_faces)
    assert back.faces.tolist() == [3, 5, 9] and back.face_weights().tolist() == [1.0, 0.5, 0.25]
    with pytest.raises(ValueError, match="body model"):
        Selection.load(tmp_path / "s.json", "smplx")


def test_mirror_takes_the_other_side(editor, monkeypatch):
    """The left hand's mirror image is exactly the right hand; a soft dab keeps its weights on both
    sides; a body mesh that is not symmetric is refused in one line."""
    body, mirror = editor.body, editor.mirror_map
    left, right = Selection.from_regions(body, "hand.L"), Selection.from_regions(body, "hand.R")
    assert torch.equal(left.mirrored(mirror).faces, right.faces)
    both = left.symmetric(mirror)
    assert torch.equal(both.mask(), left.mask() | right.mask())
    view = editor.named_view("front", 128, 128)
    dab = Selection.brush(view, view.px[left.faces.numpy()].mean(0), 10, falloff=0.5)
    pair = dab.symmetric(mirror)
    assert len(pair) == 2 * len(dab) and torch.allclose(pair.dense_weights()[mirror[dab.faces]], dab.face_weights())
    shifted = editor.body.rest_vertices
    monkeypatch.setattr(editor.body, "rest_vertices", lambda params: shifted(params) + torch.tensor([0.01, 0, 0]))
    with pytest.raises(EditError, match="not left-right symmetric"):
        Editor(editor.avatar, editor.body, None).mirror_map  # noqa: B018 - a fresh session: no cached map
