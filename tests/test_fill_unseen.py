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


@pytest.mark.parametrize("weights", [1.5, {"chest": -0.1}, {"torso": 0.5}], ids=["above 1", "negative", "no group"])
def test_front_back_weight_out_of_range_is_refused(weights):
    with pytest.raises(ValueError, match="front_back"):
        fill_unseen(np.zeros((2, 1)), np.array([True, False]), CHAIN[:1], np.zeros(2, int), _centers(2), 1, weights)


def test_front_back_weights_are_per_group():
    # The ring of the test above twice: a chest ring (faces 0-3) and a lower-body ring (4-7), same places.
    centers = np.array([[0.0, -1.0, 0.0], [0.0, 1.0, 0.0], [0.5, 0.0, 0.0], [-0.5, 0.0, 0.0]] * 2)
    values = np.array([[1.0, 0.0], [0.5, 0.5], [0.0, 1.0], [0.0, 1.0]] * 2)
    known = np.array([True, False, True, True] * 2)
    ring = np.array([[0, 2], [2, 1], [1, 3], [3, 0]])
    groups = np.repeat([FILL_GROUPS.index("chest"), FILL_GROUPS.index("lower_body")], 4)
    res = fill_unseen(values, known, np.concatenate([ring, ring + 4]), groups, centers, 1,
                      {"chest": 0.0, "lower_body": 1.0})
    np.testing.assert_allclose(res.values[1], [0.0, 1.0])  # the chest's back: its sides alone
    np.testing.assert_allclose(res.values[5], [1.0, 0.0])  # the trousers' back: their front alone


def _head(normals_and_values):
    """A head of faces in a row (centres along x, so the crown search across z finds them all)."""
    normals = np.array([n for n, _ in normals_and_values], float)
    values = np.array([[v] for _, v in normals_and_values], float)
    n = len(values)
    return normals, values, np.c_[np.arange(n) * 0.01, np.zeros(n), np.zeros(n)]


def test_the_back_of_the_head_takes_the_crown_not_the_face():
    from gma.avatar.fill import Orientation

    # Anny's axes: up +z, forward -y. Face (skin 1.0, seen), crown (hair 0.0, seen), back of the head and
    # the chin underside (unseen). The chain runs face - back - crown, so the surface alone blends them.
    normals, values, centers = _head([((0, -1, 0), 1.0), ((0, 1, 0), 0.5), ((0, 0, 1), 0.0), ((0, -0.9, -0.4), 0.5)])
    known = np.array([True, False, True, False])
    pairs = np.array([[0, 1], [1, 2], [0, 3]])
    head = np.full(4, FILL_GROUPS.index("head"))
    axes = Orientation(normals, np.array([0.0, 0.0, 1.0]), np.array([0.0, -1.0, 0.0]))
    plain = fill_unseen(values, known, pairs, head, centers, 1)
    assert plain.values[1, 0] == pytest.approx(0.5)  # between skin and hair
    res = fill_unseen(values, known, pairs, head, centers, 1, orientation=axes)
    assert res.values[1, 0] == pytest.approx(0.0)  # the crown's hair
    assert res.values[3, 0] == pytest.approx(1.0)  # the face's underside stays skin: it faces forward


def test_an_unseen_face_takes_its_mirror_faces_value():
    values = np.array([[0.2], [9.0], [9.0], [0.8]])
    known = np.array([True, False, False, True])
    mirror = np.array([3, 2, 1, 0])  # 0 <-> 3 and 1 <-> 2; neither of 1, 2 was seen
    res = fill_unseen(values, known, CHAIN[:3], np.zeros(4, int), _centers(4), 1)
    assert res.how.tolist() == [0, 1, 1, 0]
    mirror[[1, 2]] = [0, 3]  # now 1 mirrors 0 and 2 mirrors 3 (a one-way map is enough here)
    res = fill_unseen(values, known, CHAIN[:3], np.zeros(4, int), _centers(4), 1, mirror_of=mirror)
    np.testing.assert_allclose(res.values[:, 0], [0.2, 0.2, 0.8, 0.8])
    assert res.how.tolist() == [0, 4, 4, 0] and res.summary()["mirror"] == 0.5


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


def test_fill_gives_the_back_the_colour_of_its_garment(anny_body, tmp_path):
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
    again = Avatar.load(avatar.save(tmp_path / "filled.gma"), anny_body)
    assert torch.equal(again.face_seen, avatar.face_seen)
    assert torch.equal(Selection.unseen(again).faces, torch.nonzero(seen < SEEN).reshape(-1))


def test_untrained_faces_are_those_the_fit_never_changed(anny_body):
    from gma.avatar import Avatar, AvatarConfig
    from gma.edit.unseen import default_colour_faces, initial_features, untrained_faces

    avatar = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1, hidden=16), anny_body, seed=3)
    start = initial_features(avatar, seed=3)
    assert untrained_faces(avatar.model, start).all() and default_colour_faces(avatar.model, start).all()
    with torch.no_grad():
        avatar.model.f_tex[:5] += 1.0
    assert untrained_faces(avatar.model, start).sum() == avatar.model.num_faces - 5
    assert not untrained_faces(avatar.model, initial_features(avatar, seed=4)).any()  # another start


def test_unseen_selection_needs_the_record(anny_body):
    from edit_helpers import fitted_avatar

    from gma.edit import EditError, Selection

    with pytest.raises(EditError, match="no record of what"):
        Selection.unseen(fitted_avatar(anny_body))


def test_projected_area_of_a_triangle():
    from gma.core.camera import Camera
    from gma.edit.unseen import projected_areas

    cam = Camera(np.eye(4, dtype=np.float32), np.array([[100.0, 0, 50], [0, 100.0, 50], [0, 0, 1]]), 100, 100)
    verts = np.array([[0.0, 0.0, 2.0], [0.2, 0.0, 2.0], [0.0, 0.2, 2.0], [0.0, 0.0, -1.0]])
    areas = projected_areas(verts, np.array([[0, 1, 2], [0, 1, 3]]), cam)
    assert areas[0] == pytest.approx(0.5 * 10 * 10)  # 0.2 m at 2 m with f = 100 px: 10 px legs
    assert areas[1] == 0.0  # a corner behind the camera


def _front_camera(verts, size=96):
    from gma.edit.views import named_view

    return named_view("front", verts, "z", size, size)


def test_observe_faces_sees_the_front_not_the_back(anny_body, gpu):
    from gma.body.geometry import face_normals
    from gma.edit.unseen import SEEN, observe_faces, seen_score
    from gma.render.face_id import FaceIdRenderer

    params = anny_body.canonical_params(None)
    verts = anny_body.rest_vertices(params)
    from gma.body.skinning import linear_blend_skinning

    posed = linear_blend_skinning(verts, anny_body.skin_indices, anny_body.skin_weights,
                                  anny_body.bone_transforms(params)).numpy()
    renderer = FaceIdRenderer(gpu, anny_body.faces.numpy())
    cover = observe_faces(renderer, anny_body.faces, [(posed, _front_camera(posed))])
    score = seen_score(cover)
    normals = face_normals(torch.as_tensor(posed), anny_body.faces)
    torso = anny_body.region_mask("torso")
    front, back = torso & (normals[:, 1] < -0.8), torso & (normals[:, 1] > 0.3)
    assert float((score[front] >= SEEN).float().mean()) > 0.9  # seen head-on (a few hide under the arms)
    assert float(score[back].max()) == 0.0  # turned away: never counted
    twice = seen_score(observe_faces(renderer, anny_body.faces, [(posed, _front_camera(posed))] * 2))
    assert bool((twice[front] >= score[front]).all())  # more frames, more seen


def test_seen_picture_is_green_in_front_and_magenta_behind(anny_body, gpu):
    from gma.avatar import Avatar, AvatarConfig
    from gma.edit.unseen import GUESSED_COLOR, SEEN_COLOR, seen_picture

    avatar = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1, hidden=16), anny_body)
    avatar.face_seen = _front_seen(avatar, anny_body)
    pic = seen_picture(avatar, anny_body, gpu, size=64)
    assert pic.shape == (64, 256, 3)
    front, back = pic[:, :64].reshape(-1, 3), pic[:, 64:128].reshape(-1, 3)

    def hue_share(panel, color):
        person = panel[(panel < 0.99).any(1)]
        direction = color / np.linalg.norm(color)
        cosines = person @ direction / np.maximum(np.linalg.norm(person, axis=1), 1e-6)
        return float((cosines > 0.97).mean())

    assert hue_share(front, SEEN_COLOR) > 0.7 and hue_share(back, GUESSED_COLOR) > 0.7


@pytest.mark.slow
@pytest.mark.parametrize("frame, facing", [(0, -1.0), (2, 1.0)], ids=["front only", "back only"])
def test_fit_of_a_one_sided_clip_records_and_fills_the_rest(frame, facing, anny_body, gpu, tmp_path, capsys):
    import json

    from gma.avatar import Avatar
    from gma.cli import main
    from gma.synth.generate import SynthConfig, synthesize

    cfg = SynthConfig(width=48, height=48, train_frames=4, test_pose_frames=1, test_view_frames=1, supersample=1,
                      texture_size=128)
    seq = synthesize(tmp_path / "seq", cfg, ctx=gpu, body=anny_body, progress=False)
    splits = json.loads((seq.root / "splits.json").read_text())
    # A 4-frame turn: frame 0 faces the camera, frame 2 turns its back to it.
    (seq.root / "splits.json").write_text(json.dumps({**splits, "train": [frame]}))
    out = tmp_path / "me.gma"
    assert main(["fit", str(seq.root), "-o", str(out), "--quiet", "--resolution", "48", "--stage1-steps", "2",
                 "--stage2-steps", "2", "--preview-every", "0", "--avatar.feature-dim", "8",
                 "--avatar.fine-per-face", "1"]) == 0
    assert "never seen well" in capsys.readouterr().out
    avatar = Avatar.load(out, anny_body)
    guessed = avatar.info["unseen"]["guessed"]["area"]
    assert 0.3 < guessed < 0.8  # the other side, the soles, what hides under the arms
    from gma.body.geometry import face_normals
    from gma.edit.unseen import SEEN

    shown = anny_body.region_mask("torso") & (facing * face_normals(avatar.rest_vertices, anny_body.faces)[:, 1] > 0.8)
    assert float((avatar.face_seen[shown] >= SEEN).float().mean()) > 0.8
    assert main(["eval", str(out), str(seq.root), "--split", "test_view", "--resolution", "48", "--images", "0",
                 "--out", str(tmp_path / "eval")]) == 0
    assert "seen / guessed" in capsys.readouterr().out and (tmp_path / "eval" / "seen.png").is_file()
    painted = tmp_path / "painted.gma"
    assert main(["edit", str(out), "-o", str(painted), "--select", "unseen", "--paint", "#2040c0"]) == 0
    assert torch.equal(Avatar.load(painted, anny_body).face_seen, avatar.face_seen)  # edits keep the record


@pytest.mark.slow
def test_fit_of_an_upper_body_clip_fills_the_legs(anny_body, gpu, tmp_path, capsys):
    """A clip that shows only the upper body (the frames cut below the hips): the fit goes through, the
    legs are guessed from what was seen (across groups: their own group part showed nothing), no unseen
    face is left as it was, and ``gma fit`` says so."""
    import json

    import imageio.v3 as iio

    from gma.avatar import Avatar
    from gma.cli import main
    from gma.edit.unseen import SEEN
    from gma.synth.generate import SynthConfig, synthesize

    cfg = SynthConfig(width=48, height=48, train_frames=4, test_pose_frames=1, test_view_frames=1, supersample=1,
                      texture_size=128)
    seq = synthesize(tmp_path / "seq", cfg, ctx=gpu, body=anny_body, progress=False)
    for path in [*seq.image_paths, *seq.mask_paths]:
        iio.imwrite(path, iio.imread(path)[:20])  # the top rows: head and chest, no legs
    cams = json.loads((seq.root / "cameras.json").read_text())
    (seq.root / "cameras.json").write_text(json.dumps({**cams, "height": 20}))  # same K: the rows kept stay put
    out = tmp_path / "me.gma"
    assert main(["fit", str(seq.root), "-o", str(out), "--quiet", "--resolution", "48", "--stage1-steps", "2",
                 "--stage2-steps", "2", "--preview-every", "0", "--avatar.feature-dim", "8",
                 "--avatar.fine-per-face", "1"]) == 0
    printed = capsys.readouterr().out
    assert "never seen well" in printed and "no frame showed at all" in printed
    avatar = Avatar.load(out, anny_body)
    legs = anny_body.region_mask("legs")
    assert float((avatar.face_seen[legs] < SEEN).float().mean()) > 0.95
    filled = avatar.info["unseen"]["filled"]
    assert avatar.info["unseen"]["guessed"]["area"] > 0.4 and filled["across_groups"] > 0 and filled["left"] == 0
