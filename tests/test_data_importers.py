"""Importers, each on a tiny fixture written here in that dataset's real layout, plus bad inputs."""

from __future__ import annotations

import json
import os
import pickle
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np
import pytest
from PIL import Image

from gma.data import read_sequence
from gma.data.importers import import_peoplesnapshot, import_video, import_xhumans, import_zjumocap
from gma.data.importers._common import load_npy_safely
from gma.data.importers.zjumocap import _rotvec_to_matrix

W, H = 40, 32


def fake_smpl(root, kind="smpl", genders=("neutral", "male", "female"), v=30, j=24):
    """Model files with the arrays GMA reads (a real one comes from the SMPL website)."""
    rng = np.random.default_rng(1)
    (root / kind).mkdir(parents=True, exist_ok=True)
    jreg = rng.random((j, v))
    arrays = dict(
        v_template=rng.normal(size=(v, 3)),
        shapedirs=rng.normal(size=(v, 3, 10)) * 0.01,
        J_regressor=jreg / jreg.sum(1, keepdims=True),
    )
    for g in genders:
        np.savez(root / kind / f"{kind.upper()}_{g.upper()}.npz", **arrays)
    return root, arrays


def frame_image(i):
    img = np.zeros((H, W, 3), np.uint8)
    img[..., 0] = 10 * i
    img[4:12, 5:15] = (200, 100, 50)
    return img


def frame_mask():
    m = np.zeros((H, W), np.uint8)
    m[4:12, 5:15] = 1
    return m


# -- PeopleSnapshot ---------------------------------------------------------------------------------


def people_snapshot(root, t=6):
    src = root / "female-3-casual"
    (src / "images").mkdir(parents=True)
    (src / "masks").mkdir()
    w2c = np.eye(4)
    w2c[2, 3] = 3.0
    np.savez(
        src / "cameras.npz",
        intrinsic=np.array([[30.0, 0, W / 2], [0, 30, H / 2], [0, 0, 1]]),
        extrinsic=w2c,
        height=H,
        width=W,
    )
    for i in range(t):
        iio.imwrite(src / "images" / f"image_{i:04d}.png", frame_image(i))
        np.save(src / "masks" / f"mask_{i:04d}.npy", frame_mask())
    thetas = np.zeros((t, 72), np.float32)
    thetas[:, 0] = np.arange(t) * 0.1
    np.savez(
        src / "poses.npz",
        betas=np.ones((1, 10), np.float32),
        thetas=thetas,
        transl=np.zeros((t, 3), np.float32),
    )
    return src


def test_peoplesnapshot(tmp_path):
    models, _ = fake_smpl(tmp_path / "models")
    src = people_snapshot(tmp_path)
    seq = import_peoplesnapshot(src, tmp_path / "out", skip=2, test_start=4, smpl_dir=models)
    seq = read_sequence(seq.root, model_dir=models)
    assert len(seq) == 3 and seq.body.model == "smpl" and seq.body.gender == "female"
    np.testing.assert_allclose(seq.body.arrays["global_orient"][:, 0], [0.0, 0.2, 0.4], atol=1e-6)
    assert seq.body.arrays["body_pose"].shape == (3, 69) and seq.body.arrays["betas"].shape == (10,)
    assert seq.split("train") == [0, 1] and seq.split("test") == [2]
    np.testing.assert_array_equal(seq.mask(1), frame_mask().astype(np.float32))
    np.testing.assert_array_equal(seq.image(1), frame_image(2))


def test_peoplesnapshot_downscale(tmp_path):
    models, _ = fake_smpl(tmp_path / "models")
    seq = import_peoplesnapshot(people_snapshot(tmp_path), tmp_path / "out", downscale=2, smpl_dir=models)
    assert (seq.width, seq.height) == (W // 2, H // 2)
    np.testing.assert_allclose(seq.cameras.K[0, 0, 0], 15.0)
    assert 0 < seq.mask(0).sum() < seq.mask(0).size


def test_peoplesnapshot_without_smpl_files(tmp_path, monkeypatch):
    monkeypatch.delenv("GMA_SMPL_DIR", raising=False)
    src = people_snapshot(tmp_path)
    with pytest.raises(FileNotFoundError, match=r"smpl\.is\.tue\.mpg\.de"):
        import_peoplesnapshot(src, tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_peoplesnapshot_bad_pose_count(tmp_path):
    models, _ = fake_smpl(tmp_path / "models")
    src = people_snapshot(tmp_path)
    np.savez(src / "poses.npz", betas=np.zeros(10), thetas=np.zeros((4, 72)), transl=np.zeros((4, 3)))
    with pytest.raises(ValueError, match="poses.npz: 4 frames of poses, but 6 images"):
        import_peoplesnapshot(src, tmp_path / "out", smpl_dir=models)
    assert [p.name for p in tmp_path.iterdir()] != ["out"] and not (tmp_path / "out").exists()


# -- X-Humans ---------------------------------------------------------------------------------------


def xhumans_take(take, frames, betas):
    (take / "render" / "image").mkdir(parents=True)
    (take / "render" / "depth").mkdir()
    (take / "SMPLX").mkdir()
    extr = np.tile(np.eye(4)[:3], (len(frames), 1, 1))
    extr[:, 2, 3] = 2.5
    np.savez(
        take / "render" / "cameras.npz",
        intrinsic=np.array([[25.0, 0, W / 2], [0, 25, H / 2], [0, 0, 1]]),
        extrinsic=extr,
    )
    for n in frames:
        iio.imwrite(take / "render" / "image" / f"color_{n:06d}.png", frame_image(n))
        depth = np.full((H, W), 10.0, np.float32)
        depth[frame_mask() > 0] = 2.0
        Image.fromarray(depth, mode="F").save(take / "render" / "depth" / f"depth_{n:06d}.tiff")
        params = {
            "betas": betas[None],
            "global_orient": np.full((1, 3), 0.01 * n),
            "body_pose": np.zeros((1, 63)),
            "transl": np.zeros((1, 3)),
            "left_hand_pose": np.zeros((1, 45)),
            "right_hand_pose": np.zeros((1, 45)),
            "jaw_pose": np.zeros((1, 3)),
            "leye_pose": np.zeros((1, 3)),
            "reye_pose": np.zeros((1, 3)),
            "expression": np.zeros((1, 10)),
        }
        with open(take / "SMPLX" / f"mesh-f{n:05d}_smplx.pkl", "wb") as f:
            pickle.dump(params, f)  # the dataset's own format; GMA only reads these through an allow-list


def test_xhumans_subject(tmp_path):
    models, _ = fake_smpl(tmp_path / "models", "smplx")
    subject = tmp_path / "00016"
    betas = np.linspace(0, 1, 10)
    xhumans_take(subject / "train" / "Take1", [1, 2, 3], betas)
    xhumans_take(subject / "test" / "Take7", [5, 6], betas)
    (subject / "gender.txt").write_text("male\n")
    seq = read_sequence(import_xhumans(subject, tmp_path / "out", smplx_dir=models).root, model_dir=models)
    assert len(seq) == 5 and seq.body.model == "smplx" and seq.body.gender == "male"
    assert seq.split("train") == [0, 1, 2] and seq.split("test_pose") == [3, 4]
    np.testing.assert_allclose(seq.body.arrays["global_orient"][:, 0], [0.01, 0.02, 0.03, 0.05, 0.06])
    np.testing.assert_array_equal(seq.mask(4), frame_mask().astype(np.float32))
    np.testing.assert_allclose(seq.cameras.frame(3)[1][2, 3], 2.5)


def test_xhumans_rejects_code_in_pickle(tmp_path):
    models, _ = fake_smpl(tmp_path / "models", "smplx")
    take = tmp_path / "Take1"
    xhumans_take(take, [1], np.zeros(10))

    class Evil:
        # os.system rather than print: a local Ray runtime (tests/test_batch.py) replaces builtins.print
        # in this process, and the pickle would then name Ray's function instead.
        def __reduce__(self):
            return (os.system, ("echo pwned",))

    with open(take / "SMPLX" / "mesh-f00001_smplx.pkl", "wb") as f:
        pickle.dump({"betas": Evil()}, f)
    with pytest.raises(ValueError, match=r"refusing to load (posix|nt|os)\.system"):
        import_xhumans(take, tmp_path / "out", smplx_dir=models)
    assert not (tmp_path / "out").exists()


def test_xhumans_missing_params(tmp_path):
    models, _ = fake_smpl(tmp_path / "models", "smplx")
    take = tmp_path / "Take1"
    xhumans_take(take, [1, 2], np.zeros(10))
    (take / "SMPLX" / "mesh-f00002_smplx.pkl").unlink()
    with pytest.raises(FileNotFoundError, match="no SMPL-X parameters for frame 2"):
        import_xhumans(take, tmp_path / "out", smplx_dir=models)


# -- ZJU-MoCap --------------------------------------------------------------------------------------


def zju_subject(root, n_frames=4, n_views=4, rh=(0.3, -0.2, 0.5), th=(0.1, 0.2, 0.3)):
    src = root / "CoreView_377"
    Ks = [np.array([[25.0, 0, W / 2], [0, 25, H / 2], [0, 0, 1]])] * n_views
    Rs = [_rotvec_to_matrix(np.array([0, 2 * np.pi * v / n_views, 0])) for v in range(n_views)]
    Ts = [np.array([[0.0], [0.0], [3000.0]])] * n_views  # millimetres
    ims = []
    for f in range(n_frames):
        names = [f"Camera_B{v + 1}/{f:06d}.jpg" for v in range(n_views)]
        for name in names:
            (src / name).parent.mkdir(parents=True, exist_ok=True)
            iio.imwrite(src / name, frame_image(f), extension=".jpg")
            (src / "mask" / name).parent.mkdir(parents=True, exist_ok=True)
            iio.imwrite((src / "mask" / name).with_suffix(".png"), frame_mask())
        ims.append({"ims": names})
    np.save(
        src / "annots.npy", {"cams": {"K": Ks, "R": Rs, "T": Ts, "D": [np.zeros(5)] * n_views}, "ims": ims}
    )
    (src / "params").mkdir()
    for f in range(n_frames):
        np.save(
            src / "params" / f"{f}.npy",
            {
                "poses": np.zeros((1, 72)),
                "Rh": np.array([rh]),
                "Th": np.array([th]),
                "shapes": np.full((1, 10), 0.5),
            },
        )
    return src


def test_zjumocap(tmp_path):
    models, smpl = fake_smpl(tmp_path / "models")
    src = zju_subject(tmp_path)
    seq = read_sequence(
        import_zjumocap(src, tmp_path / "out", test_every=2, smpl_dir=models).root, model_dir=models
    )
    assert seq.split("train") == [0, 1, 2, 3]
    assert len(seq.split("test_view")) == 2 * 3  # frames 0 and 2, views 1, 2, 3
    np.testing.assert_allclose(seq.cameras.frame(0)[1][2, 3], 3.0)  # millimetres became metres
    # SMPL semantics (rotate about J0, then translate) must reproduce EasyMocap's (rotate about origin).
    rest = smpl["v_template"] + smpl["shapedirs"] @ np.full(10, 0.5)
    j0 = smpl["J_regressor"][0] @ rest
    R = _rotvec_to_matrix(np.array([0.3, -0.2, 0.5]))
    want = rest @ R.T + [0.1, 0.2, 0.3]
    b = seq.body.frame(0)
    got = (rest - j0) @ _rotvec_to_matrix(b["global_orient"]).T + j0 + b["transl"]
    np.testing.assert_allclose(got, want, atol=1e-5)


def test_zjumocap_missing_mask(tmp_path):
    models, _ = fake_smpl(tmp_path / "models")
    src = zju_subject(tmp_path)
    (src / "mask" / "Camera_B1" / "000001.png").unlink()
    with pytest.raises(FileNotFoundError, match="000001.png: mask for Camera_B1/000001.jpg is missing"):
        import_zjumocap(src, tmp_path / "out", smpl_dir=models)


def test_safe_npy_loader_rejects_code(tmp_path):
    class Evil:
        def __reduce__(self):
            return (print, ("pwned",))

    np.save(tmp_path / "a.npy", np.array([Evil()], dtype=object), allow_pickle=True)
    with pytest.raises(ValueError, match="cannot be read safely"):
        load_npy_safely(tmp_path / "a.npy")


# -- video ------------------------------------------------------------------------------------------

VW, VH, VT = 32, 24, 6


def write_video(path, frames, alpha=False):
    fmt = "rgba" if alpha else "rgb24"
    kw = (
        dict(codec="png", pix_fmt_out="rgba")
        if alpha
        else dict(codec="libx264", pix_fmt_out="yuv444p", output_params=["-qp", "0"])
    )
    w = imageio_ffmpeg.write_frames(str(path), (VW, VH), pix_fmt_in=fmt, macro_block_size=1, **kw)
    w.send(None)
    for f in frames:
        w.send(np.ascontiguousarray(f))
    w.close()


def video_inputs(tmp_path, t=VT):
    body = tmp_path / "params.npz"
    np.savez(body, model="anny", pose=np.tile(np.eye(4), (t, 104, 1, 1)), phenotype=np.full(6, 0.5))
    cam = tmp_path / "cam.json"
    cam.write_text(
        json.dumps(
            {"width": VW, "height": VH, "K": [[30, 0, 16], [0, 30, 12], [0, 0, 1]], "w2c": np.eye(4).tolist()}
        )
    )
    return body, cam


def test_video_with_mask_dir(tmp_path):
    frames = [np.full((VH, VW, 3), 40 * i, np.uint8) for i in range(VT)]
    write_video(tmp_path / "clip.mp4", frames)
    (tmp_path / "masks").mkdir()
    for i in range(VT):
        m = np.zeros((VH, VW), np.uint8)
        m[:, : 4 * (i + 1)] = 255
        iio.imwrite(tmp_path / "masks" / f"{i:04d}.png", m)
    body, cam = video_inputs(tmp_path)
    seq = import_video(
        tmp_path / "clip.mp4", tmp_path / "out", body=body, camera=cam, mask_dir=tmp_path / "masks", skip=2
    )
    assert len(seq) == 3 and seq.body.num_frames == 3
    assert seq.mask(1)[:, :12].min() == 1 and seq.mask(1)[:, 12:].max() == 0  # source frame 2
    assert abs(int(seq.image(2)[0, 0, 0]) - 160) <= 2


def test_video_with_alpha(tmp_path):
    frames = []
    for i in range(VT):
        f = np.zeros((VH, VW, 4), np.uint8)
        f[..., :3] = 30 * i
        f[4:20, 8:24, 3] = 255
        frames.append(f)
    write_video(tmp_path / "clip.mov", frames, alpha=True)
    body, cam = video_inputs(tmp_path)
    seq = import_video(tmp_path / "clip.mov", tmp_path / "out", body=body, camera=cam, alpha=True)
    assert len(seq) == VT and seq.mask(0).sum() == 16 * 16


def test_video_errors(tmp_path):
    write_video(tmp_path / "clip.mp4", [np.zeros((VH, VW, 3), np.uint8)] * VT)
    body, cam = video_inputs(tmp_path, t=4)
    with pytest.raises(ValueError, match="exactly one mask source"):
        import_video(tmp_path / "clip.mp4", tmp_path / "out", body=body, camera=cam)
    with pytest.raises(ValueError, match="params.npz: 4 frames of body parameters, but .* has 6 frames"):
        import_video(
            tmp_path / "clip.mp4", tmp_path / "out", body=body, camera=cam, mask_video=tmp_path / "clip.mp4"
        )
    body, cam = video_inputs(tmp_path)
    earlier = set(ffmpeg_children())   # any left by other tests' code
    with pytest.raises(ValueError, match="fully opaque") as error:
        import_video(tmp_path / "clip.mp4", tmp_path / "out", body=body, camera=cam, alpha=True)
    # The decoder stopped with the error, though its traceback (which holds the reading frames) is kept.
    assert error.traceback and set(ffmpeg_children()) <= earlier
    # Also where the error comes from the writer while the video and the mask video are being read.
    other = tmp_path / "other.json"   # cameras of another size than the video's frames
    other.write_text(json.dumps({"width": 2 * VW, "height": 2 * VH, "K": [[60, 0, 32], [0, 60, 24], [0, 0, 1]],
                                 "w2c": np.eye(4).tolist()}))
    with pytest.raises(ValueError, match="frame 0: image is 32x24, cameras say 64x48") as error:
        import_video(tmp_path / "clip.mp4", tmp_path / "out", body=body, camera=other, mask_video=tmp_path / "clip.mp4")
    assert error.traceback and set(ffmpeg_children()) <= earlier
    with pytest.raises(FileNotFoundError, match="nope.mp4: video not found"):
        import_video(tmp_path / "nope.mp4", tmp_path / "out", body=body, camera=cam, alpha=True)
    assert not (tmp_path / "out").exists()


def ffmpeg_children() -> list[int]:
    """Process ids of this process's ffmpeg children, running or ended but not yet reaped (an ffmpeg that
    wrote a small clip into its pipe and ended; its pipes stay open until it is). Linux; [] elsewhere."""
    found = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            pid, rest = stat.read_text().split(" (", 1)
        except OSError:
            continue  # ended while listed
        comm, fields = rest.rsplit(") ", 1)
        ppid = fields.split()[1]
        if int(ppid) == os.getpid() and "ffmpeg" in comm:
            found.append(int(pid))
    return found


def test_reading_stops_ffmpeg_on_errors(tmp_path):
    """A read that stops on an error (here the memory budget, after the first frame) ends its ffmpeg
    process at once, not when the error's traceback is dropped."""
    from gma.video import VideoError, read_video

    write_video(tmp_path / "clip.mp4", [np.zeros((VH, VW, 3), np.uint8)] * VT)
    earlier = set(ffmpeg_children())   # any left by other tests' code
    with pytest.raises(VideoError, match="more than this machine's memory allows") as error:
        read_video(tmp_path / "clip.mp4", max_bytes=VW * VH * 3 + 1)
    assert error.traceback and set(ffmpeg_children()) <= earlier
    frames, idx = read_video(tmp_path / "clip.mp4", end=2)  # stopped early by the selection: ended too
    assert idx == [0, 1] and set(ffmpeg_children()) <= earlier


def test_cli_import(tmp_path, capsys):
    from gma.cli import main

    models, _ = fake_smpl(tmp_path / "models")
    src = people_snapshot(tmp_path)
    args = ["import", "peoplesnapshot", str(src), str(tmp_path / "out"), "--smpl-dir", str(models)]
    assert main(args + ["--skip", "3"]) == 0
    assert "2 frames" in capsys.readouterr().out
    assert main(args) == 2
    assert "already exists" in capsys.readouterr().err
    assert main(args + ["--force"]) == 0 and len(read_sequence(tmp_path / "out", check_body_model=False)) == 6
