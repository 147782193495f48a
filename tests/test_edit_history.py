"""Edit history (gma.edit): records survive save and load, undo restores bytes exactly, redo restores
the edited bytes, revert to any record, and records hold only the touched faces."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from edit_helpers import fitted_avatar

from gma.avatar import Avatar
from gma.edit import EditError, Editor, Selection, StampPlacement, solid_shape


def _ten_edits(ed: Editor, donor: Avatar, view) -> None:
    body = ed.body
    ed.paint(Selection.from_regions(body, "torso"), "#c03030")
    ed.paint(Selection.brush(view, (128, 120), 20), "white")
    ed.transfer(donor, Selection.from_regions(body, "legs"), "tex")
    ed.set_body(shape=torch.full((6,), 0.4))
    ed.paint(Selection.box(view, (100, 60, 150, 110)), "0.1,0.5,0.9")
    ed.stamp(solid_shape("circle", (1.0, 1.0, 0.0), 32), view, StampPlacement((128, 100), 30, "px"))
    ed.transfer(donor, Selection.from_regions(body, "arms"), "geo")
    ed.set_body(expression=torch.full((52,), 0.1))
    ed.paint(Selection.from_regions(body, "head").grow(ed.graph, 1), "black")
    ed.transfer(donor, Selection.from_regions(body, "feet"), "both")


def test_ten_edits_undo_to_identical_bytes(gpu, anny_body, tmp_path):
    av = fitted_avatar(anny_body)
    original = av.to_bytes()
    donor = fitted_avatar(anny_body)
    with torch.no_grad():
        donor.model.f_tex.copy_(donor.model.f_tex.roll(7, 0))
        donor.model.f_geo.add_(0.3)
    ed = Editor(av, anny_body, gpu)
    view = ed.named_view("front", 256, 256)
    _ten_edits(ed, donor, view)
    assert [r["op"] for r in av.history] == ["paint", "paint", "transfer", "body", "paint", "stamp", "transfer",
                                              "body", "paint", "transfer"]
    edited = av.to_bytes()
    # Records keep only the touched faces' rows.
    k = av.config.feature_dim
    rec = av.history[0]
    assert rec["old"]["f_tex"]["shape"] == [rec["faces"], k] and "f_geo" not in rec["old"]

    # Through the file: load, then undo all ten.
    path = av.save(tmp_path / "edited.gma")
    back = Avatar.load(path, anny_body)
    assert back.history == av.history and back.to_bytes() == edited
    ed2 = Editor(back, anny_body, gpu)
    for _ in range(10):
        ed2.undo()
    assert back.to_bytes() == original
    with pytest.raises(EditError, match="nothing to undo"):
        ed2.undo()
    for _ in range(10):
        ed2.redo()
    assert back.to_bytes() == edited
    with pytest.raises(EditError, match="nothing to redo"):
        ed2.redo()
    # The session's decoded surfels follow undo: they match a full decode.
    ed2.revert(3)
    assert len(back.history) == 3
    full = back.decode()
    assert torch.allclose(ed2.decoded.colors, full.colors, atol=1e-6)
    assert torch.allclose(ed2.decoded.vertex_offsets, full.vertex_offsets, atol=1e-7)
    with pytest.raises(EditError, match="cannot revert"):
        ed2.revert(5)


def test_new_edit_clears_redo(gpu, anny_body):
    av = fitted_avatar(anny_body)
    ed = Editor(av, anny_body, gpu)
    sel = Selection.from_regions(anny_body, "hands")
    ed.paint(sel, "red")
    ed.undo()
    assert ed.can_redo
    ed.paint(sel, "blue")
    assert not ed.can_redo and len(av.history) == 1


def test_body_edit_validates(anny_body):
    av = fitted_avatar(anny_body)
    ed = Editor(av, anny_body)
    with pytest.raises(EditError, match="shape"):
        ed.set_body(shape=np.zeros(3))
    change = ed.set_body(shape=np.full(6, 0.7))
    assert change.body and len(change.rows) == 0 and torch.equal(av.shape, torch.full((6,), 0.7))
