"""The window-free viewer library: camera maths, selection, sources, offscreen frames and recording."""

from __future__ import annotations

import json

import numpy as np
import pytest
import viewer_helpers

from gma.core.camera import Camera
from gma.view.orbit import CameraPath, OrbitCamera
from gma.view.pipelines import clip_matrix
from gma.view.selection import (
    face_centres_on_screen,
    faces_in_box,
    faces_in_lasso,
    load_selection,
    points_in_polygon,
    save_selection,
)

small_body_source = viewer_helpers.small_body_source  # fixture

W, H = 160, 120


def test_clip_matrix_lands_on_opencv_pixels():
    cam = Camera.look_at((0.3, 0.2, -2.0), (0, 0, 0), fov_y_deg=50, width=W, height=H)
    pts = np.random.default_rng(0).uniform(-0.5, 0.5, (20, 3))
    clip = np.c_[pts, np.ones(20)] @ clip_matrix(cam, 0.01, 10.0).T.astype(np.float64)
    ndc = clip[:, :3] / clip[:, 3:]
    px = np.c_[(ndc[:, 0] + 1) * W / 2, (1 - ndc[:, 1]) * H / 2]
    pc = pts @ cam.viewmat[:3, :3].T + cam.viewmat[:3, 3]
    uv = pc @ cam.K.T
    np.testing.assert_allclose(px, uv[:, :2] / uv[:, 2:], atol=1e-3)
    assert np.all((ndc[:, 2] > 0) & (ndc[:, 2] < 1))


def test_points_in_polygon_square_and_concave():
    square = np.array([[0, 0], [10, 0], [10, 10], [0, 10]], float)
    pts = np.array([[5, 5], [11, 5], [-1, -1], [9.9, 0.1]])
    assert points_in_polygon(pts, square).tolist() == [True, False, False, True]
    ell = np.array([[0, 0], [10, 0], [10, 4], [4, 4], [4, 10], [0, 10]], float)  # an L shape
    assert points_in_polygon(np.array([[2, 8], [8, 8], [8, 2]]), ell).tolist() == [True, False, True]
    assert not points_in_polygon(pts, square[:2]).any()  # degenerate lasso selects nothing


def test_orbit_and_camera_path():
    o = OrbitCamera(np.zeros(3), 2.0, up_axis="z")
    np.testing.assert_allclose(o.eye, [0, -2, 0], atol=1e-9)  # Anny faces -Y: default view from the front
    eye0 = o.eye
    o.orbit(50, 0)
    assert not np.allclose(o.eye, eye0) and abs(np.linalg.norm(o.eye) - 2.0) < 1e-9
    o.orbit(0, 1e4)
    assert o.elevation == 89.0  # clamped short of the pole
    path = CameraPath.turntable(OrbitCamera(np.zeros(3), 2.0), 2.0)
    assert path.at(1.0).azimuth == pytest.approx(180.0)
    assert path.at(5.0).azimuth == pytest.approx(360.0)
    with pytest.raises(ValueError):
        path.add(o, 1.0)


@pytest.mark.gpu
def test_box_and_lasso_select_the_faces_inside(small_body_source):
    src = small_body_source
    orbit = OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis)
    cam = orbit.camera(W, H)
    v, f = src.posed_vertices(), src.body.faces.numpy()
    px, z, facing = face_centres_on_screen(v, f, cam)
    box = (60, 20, 100, 70)
    got = faces_in_box(v, f, cam, box)
    inside = (px[:, 0] >= 60) & (px[:, 0] <= 100) & (px[:, 1] >= 20) & (px[:, 1] <= 70)
    np.testing.assert_array_equal(got, inside & facing)
    assert 0 < got.sum() < len(f)
    through = faces_in_box(v, f, cam, box, front_only=False)
    assert through.sum() > got.sum()  # back faces of the torso lie in the same box
    lasso = np.array([[60, 20], [100, 20], [100, 70], [60, 70]], float)
    np.testing.assert_array_equal(faces_in_lasso(v, f, cam, lasso), got)


def test_selection_file_roundtrip_and_errors(tmp_path):
    path = tmp_path / "sel.json"
    save_selection(path, [5, 3, 3, 9], "anny", 10)
    assert json.loads(path.read_text())["faces"] == [3, 5, 9]
    sel = load_selection(path, "anny", 10)
    assert sel.faces.tolist() == [3, 5, 9] and sel.body_model == "anny"
    with pytest.raises(ValueError, match="smplx"):
        load_selection(path, "smplx")
    with pytest.raises(ValueError, match="10 faces"):
        load_selection(path, "anny", 11)
    with pytest.raises(ValueError, match="outside"):
        save_selection(path, [10], "anny", 10)
    (tmp_path / "bad.json").write_text("{nope")
    with pytest.raises(ValueError, match="bad.json"):
        load_selection(tmp_path / "bad.json")
    with pytest.raises(FileNotFoundError, match="missing.json"):
        load_selection(tmp_path / "missing.json")


@pytest.mark.gpu
def test_load_source_errors_name_the_file(gpu, tmp_path):
    from gma.view import load_source

    with pytest.raises(FileNotFoundError, match="nothere.ply"):
        load_source(gpu, str(tmp_path / "nothere.ply"))
    (tmp_path / "a.gma").write_bytes(b"x")
    with pytest.raises(ValueError, match="a.gma"):
        load_source(gpu, str(tmp_path / "a.gma"))
    (tmp_path / "a.obj").write_text("v 0 0 0\n")
    with pytest.raises(ValueError, match="unknown source format"):
        load_source(gpu, str(tmp_path / "a.obj"))


@pytest.mark.gpu
def test_ply_source_renders_offscreen(gpu, tmp_path):
    from gma.render.ply import save_splat_ply
    from gma.render.scenes import avatar_like_scene
    from gma.view import FrameRenderer, OrbitCamera, Scene, load_source

    s = avatar_like_scene(2000)
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"])
    src = load_source(gpu, str(tmp_path / "s.ply"))
    assert src.mesh is None
    img = FrameRenderer(gpu).render_image(Scene(src), OrbitCamera.framing(*src.bounds()).camera(W, H))
    assert img.shape == (H, W, 4) and (img[..., :3] < 250).any(axis=-1).mean() > 0.05


@pytest.mark.gpu
def test_overlays_and_highlight_change_the_image(gpu, small_body_source):
    from gma.view import FrameRenderer, OrbitCamera, Scene

    src = small_body_source
    scene = Scene(src)
    r = FrameRenderer(gpu)
    cam = OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis).camera(W, H)
    base = r.render_image(scene, cam).astype(int)
    assert (base[..., :3] < 240).any(-1).mean() > 0.05  # the body covers part of the frame
    scene.set_selection(np.nonzero(src.body.region_mask("head").numpy())[0])
    sel = r.render_image(scene, cam).astype(int)
    changed = np.abs(sel - base).max(-1) > 10
    assert changed.any() and np.nonzero(changed)[0].max() < H // 3  # only the head (top of the frame) changes
    scene.set_selection([])
    for flag in ("wireframe", "normals", "coarse"):
        setattr(scene.options, flag, True)
        assert np.abs(r.render_image(scene, cam).astype(int) - base).max() > 10, flag
        setattr(scene.options, flag, False)
    np.testing.assert_array_equal(r.render_image(scene, cam), base)  # overlays off: the same image again


@pytest.mark.gpu
def test_body_controls_pose_shape_and_playback(small_body_source):
    from gma.view.controls import BodyControls, load_motion

    src = small_body_source
    ctl = BodyControls(src)
    rest = src.posed_vertices()
    ctl.set_motion(load_motion("walk", src.body, 12))
    ctl.scrub(3)
    walked = src.posed_vertices()
    assert np.abs(walked - rest).max() > 0.02
    assert ctl.advance(1 / 30 + 1e-6) and ctl.frame == 4
    ctl.reset_pose()
    np.testing.assert_allclose(src.posed_vertices(), rest, atol=1e-5)
    ctl.set_shape(4, 1.0)  # height
    assert np.ptp(src.posed_vertices()[:, 2]) > np.ptp(rest[:, 2]) + 0.01
    ctl.set_shape(4, 0.5)
    with pytest.raises(FileNotFoundError, match="dance"):
        load_motion("dance", src.body)


@pytest.mark.gpu
def test_motion_label_names_what_plays(gpu, small_body_source, tmp_path):
    """The motion list shows what plays: a built-in motion, a file's name, canonical after a reset."""
    from gma.body.motion_files import save_motion
    from gma.view.controls import load_motion
    from viewer.state import ViewerState

    state = ViewerState(gpu, small_body_source)
    assert state.motion_label == "canonical"
    state.play_motion("walk", frames=8)
    assert state.motion_label == "walk"
    state.controls.reset_pose()
    assert state.motion_label == "canonical"
    save_motion(tmp_path / "mine.npz", load_motion("wave", small_body_source.body, 8))
    state.play_motion(str(tmp_path / "mine.npz"), frames=8)
    assert state.motion_label == "mine.npz"
    state.play_motion(None)
    assert state.motion_label == "canonical"


@pytest.mark.gpu
@pytest.mark.parametrize("out", ["clip.gif", "clip.mp4", "frames"])
def test_recorder_writes_outputs(gpu, small_body_source, tmp_path, out):
    import imageio.v3 as iio

    from gma.view import FrameRenderer, Scene
    from gma.view.record import Recorder

    src = small_body_source
    path = CameraPath.turntable(OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis), 0.3)
    rec = Recorder(FrameRenderer(gpu), Scene(src), tmp_path / out, path, 64, 48, fps=10)
    assert rec.num_frames == 3
    progress = []
    rec.run(progress.append)
    assert progress[-1] == 1.0 and not list(tmp_path.glob(".*"))  # no temporary left behind
    if out == "frames":
        files = sorted((tmp_path / out).glob("*.png"))
        assert len(files) == 3 and iio.imread(files[0]).shape == (48, 64, 3)
    else:
        frames = iio.imread(tmp_path / out, index=None)
        assert frames.shape[0] == 3 and frames.shape[1:3] == (48, 64)


@pytest.mark.gpu
def test_first_frame_is_complete_and_still_png(gpu, small_body_source, tmp_path):
    """The first frame of a recording draws every surfel although the renderer starts with too small an
    intersection capacity (it used to come out with surfels missing), and a .png is one still frame."""
    import imageio.v3 as iio

    from gma.view import FrameRenderer, Scene
    from gma.view.record import Recorder

    src = small_body_source
    path = CameraPath.turntable(OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis), 0.2, turns=0.0)
    renderer = FrameRenderer(gpu)
    renderer.rasterizer.isect_capacity_hint = 16  # far too small: the first draw drops intersections
    Recorder(renderer, Scene(src), tmp_path / "frames", path, 64, 48, fps=10).run()
    first, second = (iio.imread(p) for p in sorted((tmp_path / "frames").glob("*.png")))
    np.testing.assert_array_equal(first, second)
    Recorder(FrameRenderer(gpu), Scene(src), tmp_path / "still.png", path, 64, 48, fps=10, num_frames=1).run()
    np.testing.assert_array_equal(iio.imread(tmp_path / "still.png"), first)
    with pytest.raises(ValueError, match="one frame"):
        Recorder(FrameRenderer(gpu), Scene(src), tmp_path / "many.png", path, 64, 48, fps=10)
