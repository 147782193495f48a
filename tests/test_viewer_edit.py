"""The viewer's edit tools offscreen (no window): the methods the mouse and the panels call, on a small
avatar. Each edit reaches the GPU buffers by its touched rows only, and the frame shows it."""

from __future__ import annotations

import numpy as np
import pytest
import torch
import viewer_helpers

from gma.edit import EditError, Selection

small_avatar_file = viewer_helpers.small_avatar_file  # fixtures
avatar_state = viewer_helpers.avatar_state

pytestmark = pytest.mark.gpu

W, H = 160, 120
SIZE = (W, H)


def render(state, selection: bool = False):
    opts = state.scene.options
    shown, opts.selection = opts.selection, selection
    try:
        return state.renderer.render_image(state.scene, state.camera(W, H))
    finally:
        opts.selection = shown


def gpu_colors(state):
    src = state.source
    return state.ctx.read(src.surfels.colors, np.float32).reshape(-1, 3)[: len(src.decoded.colors)]


@pytest.mark.slow
def test_fill_paints_the_visible_selection_and_uploads_only_its_rows(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    sel = ed.select_box((60, 20, 100, 70), SIZE)
    assert 0 < len(sel) < s.source.body.num_faces // 4
    assert s.scene.selection.tolist() == sel.faces.tolist()
    before = render(s)
    up0 = s.ctx.transfers.bytes_up
    ed.set_color("#2040ff")
    change = ed.fill()
    assert ed.dirty and len(s.source.avatar.history) == 1
    assert set(change.faces.tolist()) == set(sel.faces.tolist())
    # The GPU colour buffer equals the editor's decoded colours (rows written), and changed only there.
    np.testing.assert_array_equal(gpu_colors(s), s.source.decoded.colors.numpy())
    full = s.source.poser.surfels_buf.size + s.source.surfels.colors.size
    assert s.ctx.transfers.bytes_up - up0 < 0.5 * full  # the touched rows, not the whole avatar
    after = render(s)
    changed = np.abs(after.astype(int) - before.astype(int)).max(-1) > 10
    ys, xs = np.nonzero(changed)
    assert len(xs) > 50 and xs.min() >= 50 and xs.max() <= 110 and ys.min() >= 10 and ys.max() <= 80
    blue = after[changed][:, :3].astype(int)
    assert np.median(blue[:, 2] - blue[:, 0]) > 60  # painted blue


@pytest.mark.slow
def test_brush_stroke_is_one_undoable_record_and_undo_restores_the_file(avatar_state, tmp_path):
    s, ed = avatar_state, avatar_state.edit
    original = s.source.path.read_bytes()
    ed.brush.radius = 8
    ed.set_color((0.0, 0.0, 0.0))
    ed.stroke_begin(70, 40)
    for x in range(70, 95, 4):
        ed.stroke_to(x, 45)
        ed.stroke_update(SIZE)  # once per frame in the window
    ed.stroke_end(SIZE)
    assert ed.last_stroke.updates >= 2
    assert len(s.source.avatar.history) == 1  # the whole stroke is one record
    assert s.source.avatar.history[0]["params"]["stroke"] >= 2
    painted = render(s)
    ed.undo()
    assert s.source.avatar.to_bytes() == original  # exactly the file as opened
    np.testing.assert_array_equal(gpu_colors(s), s.source.decoded.colors.numpy())
    ed.redo()
    assert np.abs(render(s).astype(int) - painted.astype(int)).max() <= 1
    # Save: atomic, with history; the copy loads with the record.
    out = ed.save(tmp_path / "edited.gma")
    assert not ed.dirty and out.is_file()
    from gma.avatar import Avatar

    assert len(Avatar.load(out).history) == 1
    ed.revert(0)
    assert ed.dirty and s.source.avatar.to_bytes() == original
    ed.redo()  # back to the state that was saved: clean again
    assert not ed.dirty


@pytest.mark.slow
def test_selection_tools_only_hit_visible_faces(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    view = ed.view(SIZE)
    sel = ed.select_box((0, 0, W, H), SIZE)
    assert view.visible[sel.faces.numpy()].all() and len(sel) == view.visible.sum()
    n = len(ed.shrink(2))
    assert 0 < n < len(sel)
    assert len(ed.grow(2)) > n
    brush = ed.select_brush((80, 50), SIZE, "replace")
    assert brush.soft and float(brush.face_weights().min()) < 1.0
    ed.invert()
    assert len(ed.selection) >= s.source.body.num_faces - len(brush)
    ed.select_region("head")
    assert len(ed.selection) > 0
    ed.clear()
    assert len(s.scene.selection) == 0
    face = view.face_at(80, 50)
    wand = ed.select_wand(80, 50, SIZE)
    assert face in wand.faces.tolist()
    with pytest.raises(EditError):
        ed.select_wand(1, 1, SIZE)  # background


@pytest.mark.slow
def test_mirror_toggle_selects_and_paints_both_sides(avatar_state):
    from gma.edit.history import record_face_ids

    s, ed = avatar_state, avatar_state.edit
    before = len(s.source.avatar.history)
    ed.mirror = True
    try:
        sel = ed.select_brush((70, 50), SIZE, "replace")
        mirror = ed._mirror_map
        dab = Selection.brush(ed.view(SIZE), (70, 50), ed.brush.radius, ed.brush.falloff)
        assert len(sel) > len(dab) and torch.equal(sel.faces, dab.symmetric(mirror).faces)
        assert bool(sel.mask()[mirror[sel.faces]].all())  # every face's mirror image is selected too
        ed.brush.radius = 6
        ed.stroke_begin(70, 40)
        ed.stroke_to(80, 44)
        ed.stroke_update(SIZE)
        ed.stroke_end(SIZE)
        ids = record_face_ids(s.source.avatar.history[-1])
        assert len(s.source.avatar.history) == before + 1
        assert set(ids.tolist()) == set(mirror[ids].tolist())  # the stroke landed on both sides
    finally:
        ed.mirror = False
        while len(s.source.avatar.history) > before:
            ed.undo()
        ed.clear()


@pytest.mark.slow
def test_eyedropper_reads_the_rendered_colour(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    img = render(s)
    ed.select_box((0, 0, W, H), SIZE)  # the overlay must not tint the picked colour
    got = ed.pick_color(80, 50, SIZE)
    np.testing.assert_allclose(got, img[50, 80, :3] / 255.0, atol=1 / 255)
    assert ed.hex_color.startswith("#") and len(ed.hex_color) == 7


@pytest.mark.slow
def test_stamp_preview_moves_and_applies_where_it_is_shown(avatar_state):
    from gma.edit import solid_shape

    s, ed = avatar_state, avatar_state.edit
    ed.set_stamp_image(solid_shape("square", (0.0, 0.8, 0.0), 32))
    ed.stamp.size = 20
    ed.move_stamp(0, -10, SIZE)  # from the centre (80, 60) to (80, 50)
    ed.rotate_stamp(30)
    ed.scale_stamp(1.5)
    assert ed.stamp.centre == (80, 50) and ed.stamp.size == pytest.approx(30)
    lines, images = ed.overlays(SIZE, "stamp")
    assert len(images) == 1
    corners = images[0].corners
    np.testing.assert_allclose(corners.mean(0), (80, 50), atol=1e-4)
    np.testing.assert_allclose(np.linalg.norm(corners[1] - corners[0]), 30, atol=1e-3)
    preview = s.renderer.render_image(s.scene, s.camera(W, H), lines=lines, images=images)
    before = render(s)
    assert np.abs(preview.astype(int) - before.astype(int)).max() > 50  # the quad is drawn
    ed.apply_stamp(SIZE)
    after = render(s)
    inside = after[45:55, 75:85, :3].astype(int)
    assert np.median(inside[..., 1] - inside[..., 0]) > 60  # green where the preview was
    far = np.abs(after.astype(int) - before.astype(int)).max(-1)
    assert far[:, :40].max() <= 1 and far[:, 120:].max() <= 1
    assert s.source.avatar.history[-1]["op"] == "stamp"


@pytest.mark.slow
def test_transfer_from_a_donor_and_a_clear_refusal(avatar_state, anny_body, tmp_path):
    from gma.avatar import Avatar
    from gma.avatar.config import AvatarConfig
    from gma.edit import Editor

    s, ed = avatar_state, avatar_state.edit
    donor = Avatar.load(s.source.path, anny_body)
    Editor(donor, anny_body, s.ctx).paint(Selection.everything(anny_body.num_faces), "#10c010")
    donor.save(tmp_path / "donor.gma")
    other = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1), anny_body, seed=5)
    other.save(tmp_path / "other.gma")
    with pytest.raises(EditError, match="do not share decoders.*gma fit --decoders"):
        ed.load_donor(tmp_path / "other.gma")
    with pytest.raises(Exception, match="no donor"):
        ed.transfer()
    ed.load_donor(tmp_path / "donor.gma")
    assert ed.donor_thumbnail is not None and ed.donor_thumbnail.shape[2] == 4
    ed.select_region("torso")
    ed.transfer_what = "tex"
    change = ed.transfer()
    f = change.faces
    torch.testing.assert_close(s.source.avatar.model.f_tex[f], donor.model.f_tex[f], rtol=0, atol=0)
    np.testing.assert_array_equal(gpu_colors(s), s.source.decoded.colors.numpy())
    _, images = ed.overlays(SIZE, "navigate")
    assert len(images) == 1  # the donor thumbnail


@pytest.mark.slow
def test_keep_body_writes_the_shape_and_undo_brings_the_sliders_back(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    ctl = s.controls
    shape0 = s.source.avatar.shape.clone()
    torch.testing.assert_close(ctl.shape, shape0)  # the viewer opens the avatar at its own shape
    ctl.set_shape(0, float(ctl.shape_range(0)[1]))
    ed.keep_body()
    assert not torch.equal(s.source.avatar.shape, shape0)
    assert s.source.avatar.history[-1]["op"] == "body"
    ed.undo()
    torch.testing.assert_close(s.source.avatar.shape, shape0)
    torch.testing.assert_close(ctl.shape, shape0)


def test_keep_body_refuses_values_outside_the_body_range(avatar_state):
    """The Body panel's "keep" goes through Editor.check_body: a NaN or out-of-range slider value (typed
    into a slider's text field) is refused in one line, and the avatar keeps its shape and history."""
    s, ed = avatar_state, avatar_state.edit
    ctl, shape0, n = s.controls, s.source.avatar.shape.clone(), len(s.source.avatar.history)
    for bad in (float("nan"), 7.0):
        ctl.shape = shape0.clone()
        ctl.shape[1] = bad
        with pytest.raises(EditError, match=r"not a finite number in \[0, 1\]"):
            ed.keep_body()
    assert len(s.source.avatar.history) == n
    torch.testing.assert_close(s.source.avatar.shape, shape0)


def test_merge_records_keeps_the_oldest_value_of_each_face():
    from gma.edit.history import make_record, record_face_ids, record_old
    from viewer.edit import merge_records

    hist = [{"op": "body"}]
    hist.append(make_record("paint", {}, torch.tensor([1, 2]), {"f_tex": torch.tensor([[1.0], [2.0]])}))
    hist.append(make_record("paint", {}, torch.tensor([2, 3]), {"f_tex": torch.tensor([[20.0], [30.0]])}))
    assert merge_records(hist, 1, {"stroke": 2}) == 3
    assert len(hist) == 2 and hist[1]["params"] == {"stroke": 2}
    assert record_face_ids(hist[1]).tolist() == [1, 2, 3]
    assert record_old(hist[1])["f_tex"].reshape(-1).tolist() == [1.0, 2.0, 30.0]


def test_stamp_corners_follow_the_sampling_rotation():
    from viewer.edit import StampState

    st = StampState(np.zeros((10, 20, 4), np.float32), "x", centre=(50, 40), size=40, rotation=90)
    c = st.corners(100, 80)
    # Counter-clockwise on screen (y down): the image's top edge (corners 0 -> 1) now points up.
    d = c[1] - c[0]
    np.testing.assert_allclose(d / np.linalg.norm(d), (0, -1), atol=1e-6)


@pytest.mark.slow
def test_background_edit_shows_a_preview_then_the_solved_rows(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    ed.background = True
    sel = ed.select_box((60, 20, 100, 70), SIZE)
    ed.set_color((0.0, 1.0, 0.0))
    assert ed.fill() is None and ed.busy  # returns at once; the solve runs on the worker thread
    rows = sel.faces.numpy()  # one surfel per face
    np.testing.assert_allclose(gpu_colors(s)[rows], np.tile([0.0, 1.0, 0.0], (len(rows), 1)), atol=1e-6)
    ed.undo()  # waits for the fill to land, then takes it back
    assert not ed.busy and len(s.source.avatar.history) == 0
    np.testing.assert_array_equal(gpu_colors(s), s.source.decoded.colors.numpy())
    ed.redo()
    assert s.source.decoded.colors[rows, 1].mean() > 0.9


@pytest.mark.slow
def test_edits_keep_buffers_and_pipelines_and_animation_plays(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    s.play_motion("walk")
    ed.select_box((50, 20, 110, 80), SIZE)  # in the pose shown now
    s.renderer.render_image(s.scene, s.camera(W, H))  # builds the highlight overlay's pipelines
    bufs = (s.source.poser.surfels_buf, s.source.surfels.colors, s.source.surfels.means)
    pipelines = dict(s.renderer.pipelines._cache)
    frame0 = s.controls.frame
    s.tick(0.2)
    assert s.controls.frame != frame0  # playing
    ed.background = True
    ed.fill()
    while ed.busy:  # the frame loop goes on while the solve runs
        s.tick(0.05)
        s.renderer.render_image(s.scene, s.camera(W, H))
        ed.poll()
    ed.wait()
    assert len(s.source.avatar.history) == 1
    assert (s.source.poser.surfels_buf, s.source.surfels.colors, s.source.surfels.means) == bufs
    assert dict(s.renderer.pipelines._cache) == pipelines
    np.testing.assert_array_equal(gpu_colors(s), s.source.decoded.colors.numpy())


@pytest.mark.slow
def test_select_unseen_highlights_what_the_fit_never_saw(avatar_state):
    s, ed = avatar_state, avatar_state.edit
    avatar = s.source.avatar
    kept = avatar.face_seen
    try:
        avatar.face_seen = None
        with pytest.raises(EditError, match="no record"):
            ed.select_unseen()
        seen = torch.ones(s.source.body.num_faces)
        seen[::3] = 0.0
        avatar.face_seen = seen
        sel = ed.select_unseen()
        assert sel.faces.tolist() == list(range(0, s.source.body.num_faces, 3))
        assert s.scene.selection.tolist() == sel.faces.tolist()  # the highlight draws it
    finally:
        avatar.face_seen = kept
        ed.clear()
def test_worker_runs_one_job_started_only_when_asked():
    """The edit worker queues one job on a thread that starts only on ``start`` (the window starts it after
    presenting the preview frame); a failed job hands its error back instead of raising on the thread."""
    import threading

    from viewer.edit.worker import EditJob, EditWorker

    gate = threading.Event()
    worker = EditWorker()
    job = EditJob("paint", lambda: gate.wait(30) and "change")
    worker.submit(job)
    assert worker.busy and not job.started
    assert worker.take_finished(start=False) is None and not job.started  # polling does not start it
    with pytest.raises(RuntimeError, match="already running"):
        worker.submit(EditJob("fill", lambda: None))
    worker.start()
    assert worker.take_finished() is None  # still running
    gate.set()
    assert worker.join() is job and job.change == "change" and job.error is None and not worker.busy
    assert worker.join() is None
    failing = EditJob("stamp", lambda: 1 / 0)
    worker.submit(failing)
    assert worker.join() is failing and isinstance(failing.error, ZeroDivisionError) and failing.change is None


def test_every_tool_has_a_key_and_errors_become_the_status_line():
    from types import SimpleNamespace

    from gma.core.errors import InputError
    from viewer.actions import TOOLS, report
    from viewer.window import _TOOL_KEYS

    assert sorted(_TOOL_KEYS.values()) == sorted(TOOLS)
    state = SimpleNamespace(message="")

    def bad():
        raise InputError("x.gma: not an avatar\nsecond line")

    assert report(state, bad) is None and state.message == "x.gma: not an avatar"
    assert report(state, lambda a, b=0: a + b, 1, b=2) == 3
    with pytest.raises(ZeroDivisionError):  # a bug is not a user error: it keeps its traceback
        report(state, lambda: 1 / 0)
