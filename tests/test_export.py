"""``gma export``: splat PLYs that render like the avatar, meshes that load, poses that resolve."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
from edit_helpers import varied_avatar

from gma.cli import main as gma_main


@pytest.fixture(scope="module")
def avatar_file(tmp_path_factory, anny_body):
    """A small avatar with varied colours, scales and offsets (random decoder weights), saved."""
    return varied_avatar(anny_body).save(tmp_path_factory.mktemp("export") / "a.gma")


def _psnr(a: np.ndarray, b: np.ndarray) -> float:
    return float(10 * np.log10(1.0 / max(np.mean((a.astype(np.float64) - b) ** 2), 1e-12)))


def _camera(anny_body, size: int = 128):
    from gma.core.camera import Camera

    # Anny is Z-up and faces -Y: look at it from the front.
    return Camera.look_at((0.0, -3.2, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov_y_deg=40.0, width=size,
                          height=size)


@pytest.mark.slow
@pytest.mark.parametrize("layout", ["3dgs", "2dgs"])
@pytest.mark.parametrize("frame", [None, 7])
def test_splat_export_renders_like_the_avatar(gpu, anny_body, avatar_file, tmp_path, layout, frame):
    """render-ply of the export equals the avatar's own GPU render (canonical and a walking frame)."""
    plyfile = pytest.importorskip("plyfile")
    from gma.avatar import Avatar
    from gma.avatar.gpu import AvatarRenderer
    from gma.body.motions import motion

    av = Avatar.load(avatar_file, anny_body)
    args = ["export", str(avatar_file), str(tmp_path / "a.ply"), "--format", layout]
    params = {}
    if frame is not None:
        walk = motion("walk", 16, anny_body)
        from gma.body.motion_files import save_motion

        save_motion(tmp_path / "walk.npz", walk)
        args += ["--motion", str(tmp_path / "walk.npz"), "--frame", str(frame)]
        params = {"pose": walk.pose[frame], "expression": walk.expression[frame]}
    assert gma_main(args) == 0
    cam = _camera(anny_body)
    (tmp_path / "cam.json").write_text(json.dumps(cam.to_json()))
    assert gma_main(["render-ply", str(tmp_path / "a.ply"), "--camera", str(tmp_path / "cam.json"),
                     "-o", str(tmp_path / "ply.png")]) == 0
    own = AvatarRenderer(gpu, av, anny_body).render(params, cam, background=(0.0, 0.0, 0.0))
    got = iio.imread(tmp_path / "ply.png")[..., :3] / 255.0
    assert own[..., :3].max() > 0.2  # the avatar is in view
    psnr = _psnr(np.round(own.clip(0, 1) * 255) / 255, got)
    assert psnr >= 40.0, psnr
    vertex = plyfile.PlyData.read(str(tmp_path / "a.ply"))["vertex"]
    assert vertex.count == len(av.decode().binding)
    scales = [p.name for p in vertex.properties if p.name.startswith("scale_")]
    assert scales == (["scale_0", "scale_1", "scale_2"] if layout == "3dgs" else ["scale_0", "scale_1"])


def test_sh_degree_3_adds_zero_rest(tmp_path):
    from gma.render.ply import load_splat_ply, save_splat_ply
    from gma.render.scenes import random_scene

    s = random_scene(20, seed=1)
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"],
                   thickness=1e-4, sh_degree=3)
    header = (tmp_path / "s.ply").read_bytes().split(b"end_header")[0].decode()
    assert "f_rest_44" in header and "f_rest_45" not in header and "scale_2" in header
    back = load_splat_ply(tmp_path / "s.ply")
    np.testing.assert_allclose(back["scales"], s["scales"], rtol=1e-4)
    np.testing.assert_allclose(back["colors"], s["colors"], atol=1e-5)


@pytest.mark.slow
@pytest.mark.parametrize("suffix,texture", [(".glb", 0), (".obj", 64), (".ply", 0)])
def test_mesh_export_loads(anny_body, avatar_file, tmp_path, suffix, texture):
    trimesh = pytest.importorskip("trimesh")
    out = tmp_path / f"m{suffix}"
    args = ["export", str(avatar_file), str(out), "--pose", "tpose", "--texture", str(texture)]
    if suffix == ".ply":
        args += ["--format", "mesh"]
    assert gma_main(args) == 0
    mesh = trimesh.load(out, force="mesh")
    assert len(mesh.faces) == anny_body.num_faces
    lo, hi = mesh.bounds
    assert hi[0] - lo[0] > 1.3  # T-pose: the arms span well over a metre
    if texture:
        assert (tmp_path / "m.mtl").is_file()
        assert mesh.visual.uv.shape == (len(mesh.vertices), 2)
    else:
        colors = mesh.visual.vertex_colors[:, :3]
        assert colors.std() > 1.0  # surfel colours, not one flat colour


@pytest.mark.slow
def test_series_from_motion(anny_body, avatar_file, tmp_path):
    from gma.body.motion_files import save_motion
    from gma.body.motions import motion

    save_motion(tmp_path / "w.npz", motion("walk", 5, anny_body))
    assert gma_main(["export", str(avatar_file), str(tmp_path / "s.ply"), "--format", "2dgs",
                     "--motion", str(tmp_path / "w.npz"), "--every", "2"]) == 0
    assert sorted(p.name for p in tmp_path.glob("s_*.ply")) == ["s_00000.ply", "s_00002.ply", "s_00004.ply"]


def test_flat_axis_stays_the_smallest(tmp_path):
    """Surfels smaller than the 3DGS thickness keep their own two scales when read back."""
    from gma.render.ply import load_splat_ply, save_splat_ply
    from gma.render.scenes import random_scene

    s = random_scene(30, seed=2)
    s["scales"] = (s["scales"] * 1e-3).astype(np.float32)  # well under 1e-4 m
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"],
                   thickness=1e-4)
    back = load_splat_ply(tmp_path / "s.ply")
    np.testing.assert_allclose(back["scales"], s["scales"], rtol=1e-4)
