"""Splat PLY reading/writing and ``gma render-ply``."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest
import torch

from gma.cli import main as gma_main
from gma.render.ply import SH_C0, load_splat_ply, save_splat_ply
from gma.render.reference import quat_to_rotmat
from gma.render.scenes import random_scene


def write_inria_ply(path, means, log_scales, quats, opacity_logits, f_dc):
    """A 3DGS-style file as the INRIA code writes it (with normals and no rest SH)."""
    n = len(means)
    cols = [("x", means[:, 0]), ("y", means[:, 1]), ("z", means[:, 2]), ("nx", np.zeros(n)), ("ny", np.zeros(n)),
            ("nz", np.zeros(n))]
    cols += [(f"f_dc_{i}", f_dc[:, i]) for i in range(3)] + [("opacity", opacity_logits)]
    cols += [(f"scale_{i}", log_scales[:, i]) for i in range(log_scales.shape[1])]
    cols += [(f"rot_{i}", quats[:, i]) for i in range(4)]
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n"
    header += "".join(f"property float {name}\n" for name, _ in cols) + "end_header\n"
    data = np.stack([c for _, c in cols], 1).astype("<f4")
    path.write_bytes(header.encode() + data.tobytes())


def test_round_trip(tmp_path):
    s = random_scene(50, seed=3)
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"])
    back = load_splat_ply(tmp_path / "s.ply")
    for key in ("means", "quats", "scales", "opacities", "colors"):
        np.testing.assert_allclose(back[key], s[key], rtol=1e-4, atol=1e-5, err_msg=key)


def test_3d_gaussians_drop_their_smallest_axis(tmp_path):
    rng = np.random.default_rng(0)
    n = 30
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)
    log_scales = np.log(rng.uniform(0.01, 0.2, (n, 3)))
    write_inria_ply(tmp_path / "g.ply", rng.normal(size=(n, 3)), log_scales, quats, np.zeros(n),
                    rng.normal(size=(n, 3)))
    out = load_splat_ply(tmp_path / "g.ply")
    R_in = quat_to_rotmat(torch.from_numpy(quats)).numpy()
    R_out = quat_to_rotmat(torch.from_numpy(out["quats"]).double()).numpy()
    drop = np.argmin(log_scales, 1)
    for i in range(n):
        keep = [a for a in (0, 1, 2) if a != drop[i]]
        # The surfel normal is the dropped axis; its two scales are the kept ones, in matching order.
        assert abs(abs(R_out[i, :, 2] @ R_in[i, :, drop[i]]) - 1) < 1e-5
        got = sorted(out["scales"][i])
        np.testing.assert_allclose(got, sorted(np.exp(log_scales[i, keep])), rtol=1e-5)
        for j in range(2):
            axis = R_out[i, :, j]
            match = [a for a in keep if abs(abs(axis @ R_in[i, :, a]) - 1) < 1e-5]
            assert match and np.isclose(out["scales"][i, j], np.exp(log_scales[i, match[0]]), rtol=1e-5)
    np.testing.assert_allclose(out["opacities"], 0.5, atol=1e-6)  # sigmoid(0)
    assert out["colors"].min() >= 0 and out["colors"].max() <= 1
    assert SH_C0 > 0


@pytest.mark.parametrize("content,match", [
    (b"not a ply", "not a PLY file"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\nend_header\n", "missing splat"),
    (b"ply\nformat binary_little_endian 1.0\nelement vertex 10\nproperty float x\n", "without 'end_header'"),
])
def test_bad_files(tmp_path, content, match):
    path = tmp_path / "bad.ply"
    path.write_bytes(content)
    with pytest.raises(ValueError, match=match) as info:
        load_splat_ply(path)
    assert str(path) in str(info.value)


def test_truncated_file(tmp_path):
    s = random_scene(20)
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"])
    data = (tmp_path / "s.ply").read_bytes()
    (tmp_path / "t.ply").write_bytes(data[:-100])
    with pytest.raises(ValueError, match="truncated"):
        load_splat_ply(tmp_path / "t.ply")
    with pytest.raises(FileNotFoundError):
        load_splat_ply(tmp_path / "missing.ply")


@pytest.mark.gpu
def test_render_ply_command(gpu, tmp_path, capsys):
    s = random_scene(400, seed=1)
    save_splat_ply(tmp_path / "s.ply", s["means"], s["quats"], s["scales"], s["opacities"], s["colors"])
    cam = {"width": 48, "height": 32, "K": [[40, 0, 24], [0, 40, 16], [0, 0, 1]], "w2c": np.eye(4).tolist()}
    (tmp_path / "cam.json").write_text(json.dumps(cam))
    assert gma_main(["render-ply", str(tmp_path / "s.ply"), "--camera", str(tmp_path / "cam.json"),
                     "-o", str(tmp_path / "out.png"), "--depth", str(tmp_path / "depth.png")]) == 0
    img = iio.imread(tmp_path / "out.png")
    assert img.shape == (32, 48, 3) and img.max() > 50
    assert iio.imread(tmp_path / "depth.png").shape == (32, 48)
    # Automatic framing when no camera is given.
    assert gma_main(["render-ply", str(tmp_path / "s.ply"), "-o", str(tmp_path / "auto.png"),
                     "--size", "40x30"]) == 0
    assert iio.imread(tmp_path / "auto.png").shape == (30, 40, 3)
    # A bad camera file is one clear line, not a traceback.
    (tmp_path / "bad.json").write_text("{")
    assert gma_main(["render-ply", str(tmp_path / "s.ply"), "--camera", str(tmp_path / "bad.json"),
                     "-o", str(tmp_path / "x.png")]) == 2
    assert "bad.json" in capsys.readouterr().err
