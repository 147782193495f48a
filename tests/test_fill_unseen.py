"""Filling the faces no training frame saw (``gma.avatar.fill`` on hand-made graphs where the answer is
known, ``gma.edit.unseen`` on the Anny body): propagation over the surface, garment groups it must not
cross, the front-to-back prior, and the all-seen / all-unseen edges."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gma.avatar.fill import FILL_GROUPS, fill_groups, fill_unseen, front_projection, harmonic_fill
from gma.avatar.fill import _adjacency as adjacency

CHAIN = np.array([[0, 1], [1, 2], [2, 3], [3, 4]])  # five faces in a row


def _centers(n: int) -> np.ndarray:
    return np.c_[np.arange(n) * 0.1, np.zeros(n), np.zeros(n)]  # far apart: no front projection


def test_harmonic_fill_interpolates_along_a_chain():
    values = np.array([[0.0], [9.0], [9.0], [9.0], [1.0]])
    known = np.array([True, False, False, False, True])
    out, filled = harmonic_fill(values, known, adjacency(CHAIN, 5))
    np.testing.assert_allclose(out[:, 0], [0.0, 0.25, 0.5, 0.75, 1.0])
    assert filled.tolist() == [False, True, True, True, False]


def test_a_group_boundary_is_not_crossed():
    values = np.array([[0.0], [9.0], [9.0], [9.0], [1.0]])
    known = np.array([True, False, False, False, True])
    groups = np.array([0, 0, 0, 1, 1])  # shirt 0-2, trousers 3-4
    res = fill_unseen(values, known, CHAIN, groups, _centers(5), depth_axis=1)
    np.testing.assert_allclose(res.values[:, 0], [0.0, 0.0, 0.0, 1.0, 1.0])
    assert res.how.tolist() == [0, 1, 1, 1, 0]


def test_a_group_part_with_nothing_seen_is_filled_across_groups():
    values = np.array([[0.2], [9.0], [9.0], [9.0]])
    known = np.array([True, False, False, False])
    groups = np.array([0, 0, 1, 1])  # only the upper body was filmed
    res = fill_unseen(values, known, CHAIN[:3], groups, _centers(4), depth_axis=1)
    np.testing.assert_allclose(res.values[:, 0], [0.2, 0.2, 0.2, 0.2])
    assert res.how.tolist() == [0, 1, 2, 2]


def test_a_component_with_nothing_seen_takes_its_group_mean():
    values = np.array([[0.0], [1.0], [7.0], [0.5]])
    known = np.array([True, True, False, True])
    groups = np.array([0, 0, 0, 1])
    pairs = np.array([[0, 1]])  # face 2 touches nothing: an eyeball of its own
    res = fill_unseen(values, known, pairs, groups, _centers(4), depth_axis=1)
    assert res.values[2, 0] == pytest.approx(0.5)  # mean of group 0's seen faces (0 and 1), not of all
    assert res.how[2] == 3


@pytest.mark.parametrize("seen", [True, False])
def test_all_seen_and_all_unseen_change_nothing(seen):
    values = np.arange(10.0).reshape(5, 2)
    known = np.full(5, seen)
    res = fill_unseen(values, known, CHAIN, np.zeros(5, int), _centers(5), depth_axis=1)
    np.testing.assert_array_equal(res.values, values)
    assert (res.how == (0 if seen else -1)).all()
    assert res.summary()["seen" if seen else "left"] == 1.0


def test_front_to_back_prior_takes_the_face_straight_through_the_body():
    # A ring of 4 faces around the depth axis y: front (y = -1, known, red), back (y = +1, unknown), and
    # two sides (known, blue). Through the body the back sees the front.
    centers = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]])
    values = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0], [0.0, 1.0]])
    known = np.array([True, False, True, True])
    pairs = np.array([[0, 2], [2, 1], [1, 3], [3, 0]])
    chest = np.zeros(4, int)  # FILL_GROUPS[0]: a projected group
    only_surface = fill_unseen(values, known, pairs, chest, centers, depth_axis=1, front_back=0.0)
    np.testing.assert_allclose(only_surface.values[1], [0.0, 1.0])  # both neighbours are blue
    both = fill_unseen(values, known, pairs, chest, centers, depth_axis=1, front_back=0.5)
    np.testing.assert_allclose(both.values[1], [0.5, 0.5])
    head = np.full(4, FILL_GROUPS.index("head"))  # not projected: face and hair differ front to back
    np.testing.assert_allclose(fill_unseen(values, known, pairs, head, centers, 1, 0.5).values[1], [0.0, 1.0])


def test_front_projection_finds_nothing_beyond_its_radius():
    centers = np.array([[0.0, -1.0, 0.0], [0.2, 1.0, 0.0]])
    out, found = front_projection(np.array([[1.0], [0.0]]), np.array([True, False]), np.array([1]), centers,
                                  depth_axis=1, radius=0.05)
    assert not found[0]
    out, found = front_projection(np.array([[1.0], [0.0]]), np.array([True, False]), np.array([1]), centers,
                                  depth_axis=1, radius=0.5)
    assert found[0] and out[0, 0] == pytest.approx(1.0)


def test_front_back_weight_out_of_range_is_refused():
    with pytest.raises(ValueError, match="front_back"):
        fill_unseen(np.zeros((2, 1)), np.array([True, False]), CHAIN[:1], np.zeros(2, int), _centers(2), 1, 1.5)


def test_fill_groups_split_the_body_without_overlap():
    regions = {n: torch.zeros(6, dtype=torch.bool) for n in ("upper_body", "arms", "lower_body", "head", "hands",
                                                             "feet")}
    regions["upper_body"][[0, 1]] = True
    regions["arms"][1] = True
    regions["lower_body"][2] = True
    regions["head"][3] = True
    regions["hands"][4] = True
    groups = fill_groups(regions)
    names = [FILL_GROUPS[g] for g in groups]
    assert names == ["chest", "arms", "lower_body", "head", "hands", "chest"]  # face 5: in no region


# -- on the Anny body ----------------------------------------------------------------------------------

def _front_seen(avatar, body) -> torch.Tensor:
    """[F] seen scores of a clip filmed straight from the front: 1 where the rest face turns to -y."""
    from gma.body.geometry import face_normals

    normals = face_normals(avatar.rest_vertices, body.faces)
    return (normals[:, 1] < -0.2).float()


def test_fill_gives_the_back_the_colour_of_its_garment(anny_body):
    from edit_helpers import GARMENTS, fitted_avatar

    from gma.avatar import Avatar
    from gma.edit import Selection
    from gma.edit.unseen import SEEN, fill_unseen_faces

    avatar = fitted_avatar(anny_body)
    seen = _front_seen(avatar, anny_body)
    m = avatar.model
    with torch.no_grad():  # the back as an unfitted clip leaves it: features nothing taught
        m.f_tex[seen < SEEN] = 0.1 * torch.randn(int((seen < SEEN).sum()), m.f_tex.shape[1],
                                                 generator=torch.Generator().manual_seed(3))
    before_seen = m.f_tex[seen >= SEEN].clone()
    back_torso = (seen < SEEN) & anny_body.region_mask("torso")
    want = torch.tensor(GARMENTS["torso"])

    def back_error():
        with torch.no_grad():
            return float((m.fine_outputs()[1][back_torso].mean((0, 1)) - want).abs().mean())

    error_before = back_error()
    summary = fill_unseen_faces(avatar, anny_body, seen, mirror=True)
    assert back_error() < 0.05 < error_before
    assert torch.equal(m.f_tex[seen >= SEEN], before_seen)  # seen faces keep their features
    assert 0.2 < summary["guessed"]["area"] < 0.8 and avatar.info["unseen"] == summary
    again = Avatar.load(avatar.save(Path_tmp() / "filled.gma"), anny_body)
    assert torch.equal(again.face_seen, avatar.face_seen)
    assert torch.equal(Selection.unseen(again).faces, torch.nonzero(seen < SEEN).reshape(-1))


def Path_tmp():
    import tempfile
    from pathlib import Path

    return Path(tempfile.mkdtemp())


def test_unseen_selection_needs_the_record(anny_body):
    from edit_helpers import fitted_avatar

    from gma.edit import EditError, Selection

    with pytest.raises(EditError, match="no record of what"):
        Selection.unseen(fitted_avatar(anny_body))
