"""Careless and hostile input against every command: each case must end with exit code 2 and one line
that names the culprit, must not touch what was already on disk, and must not leave litter. The table
grows with every bug found (one row per case; the row says what it feeds and what the line must name).

Argparse's own errors (a bad option value) print the usage before the error line: for those the last
line is checked instead of the only line.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import pytest

from gma.cli import main

pytestmark = pytest.mark.gpu


# -- what the cases run on ------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def seq_dir(tmp_path_factory, gpu, anny_body) -> Path:
    """A tiny valid sequence, copied by each case that damages it."""
    from gma.synth.generate import SynthConfig, synthesize

    cfg = SynthConfig(width=32, height=32, train_frames=2, test_pose_frames=1, test_view_frames=1,
                      supersample=1, texture_size=128)
    return synthesize(tmp_path_factory.mktemp("hostile") / "seq", cfg, ctx=gpu, body=anny_body,
                      progress=False).root


@pytest.fixture(scope="module")
def avatar_file(tmp_path_factory, anny_body) -> Path:
    from gma.avatar import Avatar, AvatarConfig

    return Avatar.create(AvatarConfig(feature_dim=4, fine_per_face=1), anny_body).save(
        tmp_path_factory.mktemp("hostile_avatar") / "a.gma")


def _snapshot(root: Path) -> dict[str, str]:
    """Every file under ``root`` with a hash of its bytes, and every folder."""
    out = {}
    for p in sorted(root.rglob("*")):
        rel = str(p.relative_to(root))
        out[rel] = hashlib.sha1(p.read_bytes()).hexdigest() if p.is_file() else "dir"
    return out


def _user_folder(path: Path) -> Path:
    path.mkdir(parents=True)
    (path / "thesis.txt").write_text("years of work")
    (path / "photos").mkdir()
    (path / "photos" / "a.jpg").write_bytes(b"\xff\xd8 not really")
    return path


def _copy_seq(seq_dir: Path, to: Path) -> Path:
    shutil.copytree(seq_dir, to)
    return to


def _ply(path: Path, header: str, body: bytes = b"") -> Path:
    path.write_bytes(header.encode() + body)
    return path


PLY_PROPS = "".join(f"property float {n}\n" for n in ("x", "y", "z", "scale_0", "scale_1", "rot_0", "rot_1",
                                                       "rot_2", "rot_3", "opacity"))


@dataclass
class Case:
    name: str
    make: object  # (tmp, seq_dir, avatar_file) -> argv list
    names: str  # text the error line must contain (the culprit)
    argparse: bool = False  # argparse's usage + error
    env: dict = field(default_factory=dict)


def _damaged_seq(fn):
    """A case maker that copies the sequence, lets ``fn(seq)`` damage it, and fits it."""

    def make(tmp, seq_dir, avatar):
        seq = _copy_seq(seq_dir, tmp / "seq")
        fn(seq)
        return ["fit", str(seq), "-o", str(tmp / "out.gma"), "--quiet", "--stage1-steps", "1", "--stage2-steps", "1"]
    return make


def _truncate_png(seq):
    p = sorted((seq / "images").iterdir())[0]
    p.write_bytes(p.read_bytes()[:60])


def _empty_masks(seq):
    for p in (seq / "masks").iterdir():
        iio.imwrite(p, np.zeros((32, 32), np.uint8))


def _infinite_k(seq):
    cams = json.loads((seq / "cameras.json").read_text())
    cams["K"][0][0] = 1e999  # JSON turns it into Infinity
    (seq / "cameras.json").write_text(json.dumps(cams))


def _random_body(seq):
    (seq / "body.npz").write_bytes(os.urandom(3000))


def _body_behind_camera(seq):
    cams = json.loads((seq / "cameras.json").read_text())
    w2c = np.asarray(cams["w2c"], np.float64)
    w2c[..., 2, 3] = -w2c[..., 2, 3] - 1.0  # the person now stands behind the camera
    cams["w2c"] = w2c.tolist()
    (seq / "cameras.json").write_text(json.dumps(cams))


def _camera_case(tmp: Path, camera, *extra: str) -> list[str]:
    """``gma import video`` of a valid 32×32 clip with ``camera`` (a dict, or raw text) as --camera."""
    clip = tmp / "clip.mp4"
    iio.imwrite(clip, np.full((2, 32, 32, 3), 128, np.uint8), fps=5, codec="libx264", macro_block_size=16)
    cam = tmp / "cam.json"
    cam.write_text(camera if isinstance(camera, str) else json.dumps(camera))
    return ["import", "video", str(clip), str(tmp / "o"), "--camera", str(cam), *extra]


def _tiny_images(seq):
    for folder in ("images", "masks"):
        for p in (seq / folder).iterdir():
            img = iio.imread(p)
            iio.imwrite(p, img[:8, :8])
    cams = json.loads((seq / "cameras.json").read_text())
    cams["width"] = cams["height"] = 8
    (seq / "cameras.json").write_text(json.dumps(cams))


def _interrupted(tmp, seq_dir, avatar):
    fit_dir = tmp / "out.fit"
    fit_dir.mkdir()
    (fit_dir / "checkpoint.safetensors").write_bytes(b"step 34")
    (fit_dir / "config.json").write_text("{}")
    return ["fit", str(seq_dir), "-o", str(tmp / "out.gma")]


def _resume_bad_config(tmp, seq_dir, avatar):
    fit_dir = tmp / "out.fit"
    fit_dir.mkdir()
    (fit_dir / "checkpoint.safetensors").write_bytes(b"step 34")
    (fit_dir / "config.json").write_text("{ not json")
    return ["fit", str(seq_dir), "-o", str(tmp / "out.gma"), "--resume"]


def _avatar_without_body(tmp, seq_dir, avatar):
    from safetensors import safe_open
    from safetensors.torch import save

    with safe_open(str(avatar), "pt") as f:
        meta = dict(f.metadata())
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    del meta["body"]
    bad = tmp / "nobody.gma"
    bad.write_bytes(save(tensors, metadata=meta))
    return ["eval", str(bad), str(seq_dir)]


def _avatar_with_bad_seen_record(tmp, seq_dir, avatar):
    from safetensors import safe_open
    from safetensors.torch import save

    with safe_open(str(avatar), "pt") as f:
        meta = dict(f.metadata())
        tensors = {k: f.get_tensor(k) for k in f.keys()}
    import torch

    tensors["face_seen"] = torch.full(tensors["model.f_tex"].shape[:1], 2.0)  # scores live in [0, 1]
    bad = tmp / "badseen.gma"
    bad.write_bytes(save(tensors, metadata=meta))
    return ["edit", str(bad), "-o", str(tmp / "out.gma"), "--select", "unseen", "--paint", "red"]


def _poisoned_avatar(avatar: Path, to: Path, key: str = "model.f_tex", value: float = float("nan"),
                     count: int = 812, info: dict | None = None) -> Path:
    """A copy of ``avatar`` whose tensor ``key`` holds ``count`` values ``value`` (NaN, inf), written past
    GMA's own checks (as another tool or a bit flip would); ``info`` replaces its info metadata."""
    from safetensors import safe_open
    from safetensors.torch import save

    with safe_open(str(avatar), "pt") as f:
        meta = dict(f.metadata())
        tensors = {k: f.get_tensor(k).clone() for k in f.keys()}
    tensors[key].view(-1)[:count] = value
    if info is not None:
        meta["info"] = json.dumps(info)
    to.write_bytes(save(tensors, metadata=meta))
    return to


def _edit(avatar, tmp, *extra: str) -> list[str]:
    return ["edit", str(avatar), "-o", str(tmp / "out.gma"), "--view-size", "64", *extra]


def _nan_ply(tmp: Path, row: bytes) -> Path:
    """An ASCII splat PLY of one vertex with the values ``row`` (x y z scale_0 scale_1 rot_0..3 opacity)."""
    return _ply(tmp / "n.ply", "ply\nformat ascii 1.0\nelement vertex 1\n" + PLY_PROPS + "end_header\n", row + b"\n")


def _bvh(tmp: Path, frame_time: str = "0.1", offset: str = "0 0 0", values: str = "0 0 0\n0 0 0") -> Path:
    """A one-joint BVH of two frames, with the given frame time, root OFFSET and channel values."""
    return _ply(tmp / "b.bvh", f"HIERARCHY\nROOT Hips\n{{\nOFFSET {offset}\nCHANNELS 3 Zrotation Xrotation "
                               f"Yrotation\n}}\nMOTION\nFrames: 2\nFrame Time: {frame_time}\n{values}\n")


FIFTY_TWO = ",".join(["0"] * 51)  # all but one facial action, for --expression cases


BAD_BVH = "HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 1 Xrotation\n}\nMOTION\nFrames: 2\nFrame Time: 0.1\n0\n"


def _npz(path: Path, **arrays) -> Path:
    np.savez(path, **arrays)
    return path


CASES = [
    # gma synth
    Case("synth --force over a user's folder",
         lambda t, s, a: ["synth", str(_user_folder(t / "mine")), "--force", "--size", "32"], "mine"),
    Case("synth . --force", lambda t, s, a: ["synth", ".", "--force", "--size", "32"], "current folder"),
    Case("synth over an existing sequence without --force",
         lambda t, s, a: ["synth", str(_copy_seq(s, t / "seq")), "--size", "32"], "already exists"),
    Case("synth under a file", lambda t, s, a: ["synth", str(_ply(t / "f", "x")) + "/seq"], "is a file"),
    Case("synth --frames 0", lambda t, s, a: ["synth", str(t / "n"), "--frames", "0"], "--frames", argparse=True),
    Case("synth --size 0", lambda t, s, a: ["synth", str(t / "n"), "--size", "0"], "--size", argparse=True),
    # gma fit: outputs
    Case("fit over an existing avatar", lambda t, s, a: ["fit", str(s), "-o", str(shutil.copy(a, t / "x.gma"))],
         "already exists"),
    Case("fit -o a folder", lambda t, s, a: ["fit", str(s), "-o", str(_user_folder(t / "dir.gma"))], "is a folder"),
    Case("fit -o not .gma", lambda t, s, a: ["fit", str(s), "-o", str(t / "a.txt")], "must end in .gma"),
    Case("fit again after an interrupted fit", _interrupted, "interrupted fit exists"),
    Case("fit --resume with a corrupt config.json", _resume_bad_config, "config.json"),
    Case("fit --resume --force", lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--resume", "--force"],
         "contradict"),
    # gma fit: inputs
    Case("fit a missing sequence", lambda t, s, a: ["fit", str(t / "nope"), "-o", str(t / "o.gma")], "nope"),
    Case("fit a truncated PNG", _damaged_seq(_truncate_png), "000000.png"),
    Case("fit all-empty masks", _damaged_seq(_empty_masks), "covers no pixel"),
    Case("fit an infinite focal length", _damaged_seq(_infinite_k), "cameras.json"),
    Case("fit a body.npz of random bytes", _damaged_seq(_random_body), "body.npz"),
    Case("fit a body behind the camera", _damaged_seq(_body_behind_camera), "behind the camera"),
    Case("fit 8x8 images", _damaged_seq(_tiny_images), "too small"),
    # gma eval
    Case("eval an avatar without body metadata", _avatar_without_body, "nobody.gma"),
    Case("edit an avatar whose seen record is out of range", _avatar_with_bad_seen_record, "badseen.gma"),
    Case("edit --select unseen on an avatar without the record",
         lambda t, s, a: ["edit", str(a), "-o", str(t / "o.gma"), "--select", "unseen", "--paint", "red"],
         "no record of what"),
    Case("eval random bytes as an avatar",
         lambda t, s, a: ["eval", str(_ply(t / "r.gma", "garbage")), str(s)], "r.gma"),
    Case("eval a split the sequence lacks", lambda t, s, a: ["eval", str(a), str(s), "--split", "nosuch"],
         "'nosuch'"),
    # gma render
    Case("render --fps 0", lambda t, s, a: ["render", "body:anny", "-o", str(t / "o.mp4"), "--fps", "0"], "--fps",
         argparse=True),
    Case("render a billion frames", lambda t, s, a: ["render", "body:anny", "-o", str(t / "o.mp4"), "--seconds",
                                                     "1e6", "--fps", "1000"], "--seconds"),
    Case("render --size 100000", lambda t, s, a: ["render", str(a), "-o", str(t / "o.mp4"), "--size", "100000"],
         "100000x100000"),
    Case("render over an existing video",
         lambda t, s, a: ["render", str(a), "-o", str(_ply(t / "o.mp4", "old video"))], "already exists"),
    Case("render --force into a user's folder",
         lambda t, s, a: ["render", str(a), "-o", str(_user_folder(t / "frames")), "--force"], "frames"),
    Case("render to an unknown format", lambda t, s, a: ["render", str(a), "-o", str(t / "o.txt")], "o.txt"),
    Case("render a bad background", lambda t, s, a: ["render", str(a), "-o", str(t / "o.mp4"), "--background",
                                                     "2,0,0"], "--background"),
    # gma render-ply: broken headers
    Case("ply without a vertex count",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat binary_little_endian 1.0\nelement vertex\n"
                                                 + PLY_PROPS + "end_header\n")), "-o", str(t / "o.png")], "a.ply"),
    Case("ply without a format",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat\nelement vertex 1\n" + PLY_PROPS
                                                 + "end_header\n")), "-o", str(t / "o.png")], "a.ply"),
    Case("ply property without a name",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1\n"
                                                 "property float\nend_header\n")), "-o", str(t / "o.png")], "a.ply"),
    Case("ply with 0 vertices",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 0\n"
                                                 + PLY_PROPS + "end_header\n")), "-o", str(t / "o.png")], "0 vertices"),
    Case("ply with 10^11 vertices",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat binary_little_endian 1.0\nelement vertex "
                                                 "100000000000\n" + PLY_PROPS + "end_header\n")), "-o",
                          str(t / "o.png")], "a.ply"),
    Case("ascii ply with words for numbers",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\n" + PLY_PROPS
                                                 + "end_header\n", b"a b c d e f g h i j\n")), "-o", str(t / "o.png")],
         "a.ply"),
    Case("render-ply over an existing image",
         lambda t, s, a: ["render-ply", str(_ply(t / "a.ply", "ply\nformat ascii 1.0\nelement vertex 1\n" + PLY_PROPS
                                                 + "end_header\n", b"0 0 0 0 0 1 0 0 0 0\n")), "-o",
                          str(_ply(t / "keep.png", "old"))], "keep.png"),
    # gma body
    Case("body export-obj over an existing file",
         lambda t, s, a: ["body", "export-obj", str(_ply(t / "b.obj", "mine"))], "already exists"),
    Case("body export-obj past the motion's end",
         lambda t, s, a: ["body", "export-obj", str(t / "b.obj"), "--motion", "walk", "--frame", "200"], "--frame"),
    # gma view (no window is opened: every case fails before)
    Case("view --size 100000", lambda t, s, a: ["view", str(a), "--size", "100000"], "100000x100000"),
    Case("view --target-fps nan", lambda t, s, a: ["view", str(a), "--target-fps", "nan"], "--target-fps",
         argparse=True),
    Case("view without a display", lambda t, s, a: ["view", str(a), "--frames", "1"], "no display",
         env={"DISPLAY": None, "WAYLAND_DISPLAY": None}),
    # gma import
    Case("import a missing video", lambda t, s, a: ["import", "video", str(t / "none.mp4"), str(t / "o")],
         "none.mp4"),
    Case("import --downscale 0", lambda t, s, a: ["import", "video", str(a), str(t / "o"), "--downscale", "0"],
         "--downscale", argparse=True),
    Case("import --focal -100", lambda t, s, a: ["import", "video", str(a), str(t / "o"), "--focal", "-100"],
         "--focal", argparse=True),
    Case("import --smooth-frames -1",
         lambda t, s, a: ["import", "video", str(a), str(t / "o"), "--smooth-frames", "-1"], "--smooth-frames",
         argparse=True),
    Case("import --smooth-frames 1.5",
         lambda t, s, a: ["import", "video", str(a), str(t / "o"), "--smooth-frames", "1.5"], "--smooth-frames",
         argparse=True),
    Case("import motion --smooth-frames nan",
         lambda t, s, a: ["import", "motion", str(a), str(t / "m.npz"), "--smooth-frames", "nan"], "--smooth-frames",
         argparse=True),
    Case("import --force over a user's folder",
         lambda t, s, a: ["import", "video", str(a), str(_user_folder(t / "mine")), "--force"], "mine"),
    # gma import video --camera: a camera file of intrinsics
    Case("import --camera without fy", lambda t, s, a: _camera_case(t, {"fx": 30, "cx": 16, "cy": 16}), "cam.json"),
    Case("import --camera with a NaN focal",
         lambda t, s, a: _camera_case(t, {"fx": float("nan"), "fy": 30, "cx": 16, "cy": 16}), "cam.json"),
    Case("import --camera with a negative focal",
         lambda t, s, a: _camera_case(t, {"fx": -30, "fy": -30, "cx": 16, "cy": 16}), "cam.json"),
    Case("import --camera with a typo'd key",
         lambda t, s, a: _camera_case(t, {"fx": 30, "fy": 30, "cx": 16, "cy": 16, "k_1": 0.1}), "cam.json"),
    Case("import --camera that is not JSON", lambda t, s, a: _camera_case(t, "fx=30"), "cam.json"),
    Case("import --camera with --focal",
         lambda t, s, a: _camera_case(t, {"fx": 30, "fy": 30, "cx": 16, "cy": 16}, "--focal", "30"), "cam.json"),
    Case("import --camera with the principal point outside the frame",
         lambda t, s, a: _camera_case(t, {"fx": 30, "fy": 30, "cx": 400, "cy": 16}), "cam.json"),
    Case("import --camera with absurd distortion",
         lambda t, s, a: _camera_case(t, {"fx": 30, "fy": 30, "cx": 16, "cy": 16, "k1": 50}), "cam.json"),
    Case("import --camera calibrated for another frame size",
         lambda t, s, a: _camera_case(t, {"fx": 30, "fy": 30, "cx": 16, "cy": 16, "width": 1920, "height": 1080}),
         "cam.json"),
    # gma import motion
    Case("import motion from a missing file", lambda t, s, a: ["import", "motion", str(t / "none.bvh"),
                                                                str(t / "m.npz")], "none.bvh"),
    Case("import motion to a .txt", lambda t, s, a: ["import", "motion", str(_ply(t / "b.bvh", "x")),
                                                      str(t / "m.txt")], "m.txt"),
    Case("import motion from a broken BVH", lambda t, s, a: ["import", "motion", str(_ply(t / "b.bvh", BAD_BVH)),
                                                              str(t / "m.npz")], "b.bvh"),
    Case("import motion from an npz with odd poses",
         lambda t, s, a: ["import", "motion", str(_npz(t / "p.npz", poses=np.zeros((3, 7)))), str(t / "m.npz")],
         "poses"),
    Case("import motion from a video that is not one",
         lambda t, s, a: ["import", "motion", str(_ply(t / "clip.mp4", "not a video")), str(t / "m.npz")],
         "clip.mp4"),
    Case("import motion over an existing file",
         lambda t, s, a: ["import", "motion", str(_ply(t / "b.bvh", BAD_BVH)), str(_ply(t / "m.npz", "old"))],
         "already exists"),
    # gma export
    Case("export to an unknown format", lambda t, s, a: ["export", str(a), str(t / "o.txt")], "o.txt"),
    Case("export splats to a .glb", lambda t, s, a: ["export", str(a), str(t / "o.glb"), "--format", "2dgs"],
         "o.glb"),
    Case("export a missing avatar", lambda t, s, a: ["export", str(t / "none.gma"), str(t / "o.ply")], "none.gma"),
    Case("export over an existing file", lambda t, s, a: ["export", str(a), str(_ply(t / "o.ply", "old"))],
         "already exists"),
    Case("export --every without --motion", lambda t, s, a: ["export", str(a), str(t / "o.ply"), "--every", "2"],
         "--every"),
    Case("export a broken BVH's motion",
         lambda t, s, a: ["export", str(a), str(t / "o.ply"), "--motion", str(_ply(t / "b.bvh", BAD_BVH))], "b.bvh"),
    Case("export a frame of an avatar without its sequence",
         lambda t, s, a: ["export", str(a), str(t / "o.ply"), "--frame", "3"], "--motion"),
    # gma export: a web page
    Case("export a page over an existing file",
         lambda t, s, a: ["export", str(a), str(_ply(t / "o.html", "<p>mine</p>"))], "already exists"),
    Case("export a page of an avatar that does not read",
         lambda t, s, a: ["export", str(_ply(t / "bad.gma", "not an avatar")), str(t / "o.html")], "bad.gma"),
    Case("export a page with a motion that does not parse",
         lambda t, s, a: ["export", str(a), str(t / "o.html"), "--motion", str(_ply(t / "b.bvh", BAD_BVH))], "b.bvh"),
    Case("export a page with an unknown motion",
         lambda t, s, a: ["export", str(a), str(t / "o.html"), "--motion", "moonwalk"], "moonwalk"),
    Case("export a page with --frame", lambda t, s, a: ["export", str(a), str(t / "o.html"), "--frame", "3"],
         "--frame"),
    # gma render: stills and motion frames
    Case("render a .png of many frames", lambda t, s, a: ["render", str(a), "-o", str(t / "o.png")], "o.png"),
    Case("render --frame without --motion", lambda t, s, a: ["render", str(a), "-o", str(t / "o.png"), "--seconds",
                                                             "0", "--frame", "3"], "--frame"),
    # Non-finite avatars (issue 65): refused on reading, naming the tensor, by every command
    Case("edit an avatar of NaN features",
         lambda t, s, a: _edit(_poisoned_avatar(a, t / "n.gma"), t, "--select", "region:torso", "--paint", "red"),
         "f_tex holds 812 NaN values"),
    Case("edit an avatar of NaN decoder weights",
         lambda t, s, a: _edit(_poisoned_avatar(a, t / "n.gma", "model.T_color.0.weight"), t, "--shape",
                               "0.5,0.5,0.5,0.5,0.5,0.5"), "T_color.0.weight holds"),
    Case("edit an avatar of infinite geometry features",
         lambda t, s, a: _edit(_poisoned_avatar(a, t / "n.gma", "model.f_geo", float("inf"), 1), t, "--history"),
         "f_geo holds 1 infinite value"),
    Case("edit an avatar whose stored expression is NaN",
         lambda t, s, a: _edit(_poisoned_avatar(a, t / "n.gma", count=0, info={"expression": [float("nan")] * 52}),
                               t, "--history"), "expression"),
    Case("edit --transfer from a NaN donor",
         lambda t, s, a: _edit(a, t, "--select", "region:torso", "--transfer", str(_poisoned_avatar(a, t / "d.gma"))),
         "d.gma: f_tex"),
    Case("export an avatar of NaN features",
         lambda t, s, a: ["export", str(_poisoned_avatar(a, t / "n.gma")), str(t / "o.ply")], "f_tex holds"),
    Case("export an avatar of NaN decoder weights as a mesh",
         lambda t, s, a: ["export", str(_poisoned_avatar(a, t / "n.gma", "model.F_coarse.2.bias")), str(t / "o.glb")],
         "F_coarse.2.bias holds"),
    Case("export an avatar of an infinite body shape",
         lambda t, s, a: ["export", str(_poisoned_avatar(a, t / "n.gma", "shape", float("inf"), 1)), str(t / "o.ply")],
         "shape holds 1 infinite value"),
    Case("eval an avatar of NaN features",
         lambda t, s, a: ["eval", str(_poisoned_avatar(a, t / "n.gma")), str(s)], "f_tex holds"),
    Case("render an avatar of NaN features",
         lambda t, s, a: ["render", str(_poisoned_avatar(a, t / "n.gma")), "-o", str(t / "o.mp4")], "f_tex holds"),
    Case("view an avatar of NaN features", lambda t, s, a: ["view", str(_poisoned_avatar(a, t / "n.gma"))],
         "f_tex holds"),
    # Splat PLYs of NaN / inf: refused naming the property
    Case("render-ply a NaN position",
         lambda t, s, a: ["render-ply", str(_nan_ply(t, b"0 0 nan 0 0 1 0 0 0 0")), "-o", str(t / "o.png")],
         "property 'z' holds 1 NaN value"),
    Case("render-ply a NaN rotation (was taken for the identity)",
         lambda t, s, a: ["render-ply", str(_nan_ply(t, b"0 0 0 0 0 nan 0 0 0 0")), "-o", str(t / "o.png")],
         "property 'rot_0'"),
    Case("render-ply an infinite scale",
         lambda t, s, a: ["render-ply", str(_nan_ply(t, b"0 0 0 inf 0 1 0 0 0 0")), "-o", str(t / "o.png")],
         "property 'scale_0' holds 1 infinite value"),
    Case("render-ply a scale that overflows",
         lambda t, s, a: ["render-ply", str(_nan_ply(t, b"0 0 0 900 0 1 0 0 0 0")), "-o", str(t / "o.png")],
         "values too large"),
    Case("render a NaN splat PLY",
         lambda t, s, a: ["render", str(_nan_ply(t, b"0 0 0 0 0 1 0 0 0 nan")), "-o", str(t / "o.mp4")],
         "property 'opacity'"),
    Case("view a NaN splat PLY", lambda t, s, a: ["view", str(_nan_ply(t, b"nan 0 0 0 0 1 0 0 0 0"))],
         "property 'x'"),
    # gma edit: body values against the body's ranges (Anny: [0, 1])
    Case("edit --shape with a NaN", lambda t, s, a: _edit(a, t, "--shape", "nan,0.5,0.5,0.5,0.5,0.5"),
         "'gender' is nan, not a finite number in [0, 1]"),
    Case("edit --shape out of range", lambda t, s, a: _edit(a, t, "--shape", "5,5,5,5,5,5"),
         "'gender' is 5, not a finite number in [0, 1]"),
    Case("edit --shape with an infinity", lambda t, s, a: _edit(a, t, "--shape", "0.5,0.5,0.5,0.5,0.5,inf"),
         "not a finite number in [0, 1]"),
    Case("edit --shape of two values", lambda t, s, a: _edit(a, t, "--shape", "0.5,0.5"), "shape"),
    Case("edit --shape of words", lambda t, s, a: _edit(a, t, "--shape", "tall"), "--shape"),
    Case("edit --expression of one value", lambda t, s, a: _edit(a, t, "--expression", "2"), "expression"),
    Case("edit --expression out of range", lambda t, s, a: _edit(a, t, "--expression", FIFTY_TWO + ",2"),
         "is 2, not a finite number in [0, 1]"),
    Case("edit --expression with a NaN", lambda t, s, a: _edit(a, t, "--expression", FIFTY_TWO + ",nan"),
         "is nan, not a finite number in [0, 1]"),
    Case("edit --shape with a paint: checked before the paint",
         lambda t, s, a: _edit(a, t, "--select", "region:torso", "--paint", "red", "--shape=-1,0,0,0,0,0"),
         "'gender' is -1"),
    # gma edit: sizes, rotations, tolerances, counts
    Case("edit --stamp --size 1e9m", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--size", "1e9m"),
         "--size 1e9m: must lie in (0, 4] m"),
    Case("edit --stamp --size infm", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--size", "infm"),
         "--size"),
    Case("edit --stamp --size nancm", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--size", "nancm"),
         "--size"),
    Case("edit --stamp --size 1e7px", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--size", "1e7px"),
         "(0, 16384] px"),
    Case("edit --stamp --rotation nan", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--rotation", "nan"),
         "--rotation: must lie in [-360, 360] degrees"),
    Case("edit --stamp --rotation 1e9", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--rotation", "1e9"),
         "--rotation"),
    Case("edit --stamp --at nan,3", lambda t, s, a: _edit(a, t, "--stamp", "shape:circle", "--at", "nan,3"), "--at"),
    Case("edit --wand-tolerance nan",
         lambda t, s, a: _edit(a, t, "--select", "wand:front@32,32", "--wand-tolerance", "nan", "--paint", "red"),
         "--wand-tolerance"),
    Case("edit --wand-tolerance 5",
         lambda t, s, a: _edit(a, t, "--select", "wand:front@32,32", "--wand-tolerance", "5", "--paint", "red"),
         "--wand-tolerance: must lie in [0, 1.73205]"),
    Case("edit --grow -1", lambda t, s, a: _edit(a, t, "--select", "all", "--grow", "-1", "--paint", "red"),
         "--grow: must lie in [0, 100] rings"),
    Case("edit --shrink 1000000", lambda t, s, a: _edit(a, t, "--select", "all", "--shrink", "1000000", "--paint",
                                                         "red"), "--shrink"),
    Case("edit --view-size 100000", lambda t, s, a: _edit(a, t, "--select", "box:front@0,0,9,9", "--paint", "red",
                                                           "--view-size", "100000"), "--view-size"),
    Case("edit a brush of NaN radius", lambda t, s, a: _edit(a, t, "--select", "brush:front@32,32,nan", "--paint",
                                                              "red"), "brush radius"),
    Case("edit a brush of huge radius", lambda t, s, a: _edit(a, t, "--select", "brush:front@32,32,1e12", "--paint",
                                                               "red"), "brush radius: must lie in (0, 16384] px"),
    Case("edit a box with an infinite corner",
         lambda t, s, a: _edit(a, t, "--select", "box:front@0,0,inf,9", "--paint", "red"), "box"),
    Case("edit a wand at a NaN pixel",
         lambda t, s, a: _edit(a, t, "--select", "wand:front@nan,3", "--paint", "red"), "wand pixel"),
    Case("edit --paint of a NaN colour",
         lambda t, s, a: _edit(a, t, "--select", "region:torso", "--paint", "nan,0,0"), "three values in [0, 1]"),
    # gma import motion: non-finite values name the input, not the output
    Case("import motion from a BVH of NaN angles",
         lambda t, s, a: ["import", "motion", str(_bvh(t, values="0 nan 0\n0 0 0")), str(t / "m.npz")], "b.bvh"),
    Case("import motion from a BVH of infinite frame time",
         lambda t, s, a: ["import", "motion", str(_bvh(t, frame_time="inf")), str(t / "m.npz")], "b.bvh"),
    Case("import motion from a BVH of NaN offset",
         lambda t, s, a: ["import", "motion", str(_bvh(t, offset="0 nan 0")), str(t / "m.npz")], "non-finite OFFSET"),
    Case("import motion from an npz of NaN poses",
         lambda t, s, a: ["import", "motion", str(_npz(t / "p.npz", poses=np.full((3, 66), np.nan),
                                                       trans=np.zeros((3, 3)))), str(t / "m.npz")], "p.npz"),
    Case("import motion from an npz of infinite frame rate",
         lambda t, s, a: ["import", "motion", str(_npz(t / "p.npz", poses=np.zeros((3, 66)), trans=np.zeros((3, 3)),
                                                       mocap_framerate=np.inf)), str(t / "m.npz")], "p.npz"),
    Case("import motion --fps nan", lambda t, s, a: ["import", "motion", str(_bvh(t)), str(t / "m.npz"), "--fps",
                                                      "nan"], "--fps", argparse=True),
    # gma batch: refused before Ray starts or anything is written
    Case("batch --decoders of NaN weights",
         lambda t, s, a: ["batch", str(s), "-o", str(t / "b"), "--decoders",
                          str(_poisoned_avatar(a, t / "dec.gma", "model.T_color.0.weight"))], "T_color.0.weight holds"),
    Case("batch --decoders of random bytes",
         lambda t, s, a: ["batch", str(s), "-o", str(t / "b"), "--decoders", str(_ply(t / "dec.gma", "garbage"))],
         "dec.gma"),
    Case("batch --lr-features nan", lambda t, s, a: ["batch", str(s), "-o", str(t / "b"), "--lr-features", "nan"],
         "--lr-features"),
    Case("batch --weights2.l1 inf", lambda t, s, a: ["batch", str(s), "-o", str(t / "b"), "--weights2.l1", "inf"],
         "--weights2.l1"),
    Case("batch a missing sequence", lambda t, s, a: ["batch", str(t / "gone"), "-o", str(t / "b")], "gone"),
    Case("batch an unknown step", lambda t, s, a: ["batch", str(s), "-o", str(t / "b"), "--steps", "fit,fly"],
         "--steps"),
    Case("batch one sequence twice", lambda t, s, a: ["batch", str(s), str(s), "-o", str(t / "b")], "given twice"),
    Case("fit --lr-decoders nan", lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--lr-decoders", "nan"],
         "--lr-decoders"),
    Case("fit --preset of no such name", lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--preset", "best"],
         "'best'"),
    Case("fit --colour.refine maybe",
         lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--colour.refine", "maybe"], "--colour.refine"),
    Case("fit --colour-edge -1", lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--colour-edge", "-1"],
         "--colour-edge"),
    Case("fit --colour.prior nan", lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--colour.prior", "nan"],
         "--colour.prior"),
    Case("fit --stage1-resolution 4",
         lambda t, s, a: ["fit", str(s), "-o", str(t / "o.gma"), "--stage1-resolution", "4"], "--stage1-resolution"),
    Case("eval --refine-colour maybe",
         lambda t, s, a: ["eval", str(a), str(s), "--refine-poses", "1", "--refine-colour", "maybe"], "--refine-colour",
         argparse=True),
    Case("eval --refine-resolution 4",
         lambda t, s, a: ["eval", str(a), str(s), "--refine-poses", "1", "--refine-resolution", "4"],
         "--refine-resolution"),
]


@pytest.mark.parametrize("case", CASES, ids=[c.name for c in CASES])
def test_hostile_input(case, tmp_path, seq_dir, avatar_file, capsys, monkeypatch):
    work = tmp_path / "w"
    work.mkdir()
    monkeypatch.chdir(work)
    for key, value in case.env.items():
        if value is None:
            monkeypatch.delenv(key, raising=False)
        else:
            monkeypatch.setenv(key, value)
    argv = case.make(work, seq_dir, avatar_file)
    before, seq_before = _snapshot(work), _snapshot(seq_dir)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code
    # A warning a user would see is a line more (Python's default filters hide these four categories;
    # glfw's errors came as warnings before the viewer's own line).
    hidden = (DeprecationWarning, PendingDeprecationWarning, ImportWarning, ResourceWarning)
    shown = [f"{w.category.__name__}: {w.message}" for w in caught if not issubclass(w.category, hidden)]
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()] + shown
    assert code == 2, f"exit {code}: {err}"
    assert err, "no message"
    line = err[-1]
    if not case.argparse:
        assert len(err) == 1, f"more than one line: {err}"
    assert "error:" in line and case.names in line, line
    # Nothing that existed changed, and nothing new is left behind but what the case itself made.
    after = _snapshot(work)
    assert {k: v for k, v in after.items() if k in before} == before
    litter = [k for k in after if k not in before and (k.startswith(".") or "/." in k or k.endswith(".work"))]
    assert not litter, litter
    assert _snapshot(seq_dir) == seq_before


def test_debug_shows_the_traceback(tmp_path, capsys):
    with pytest.raises(FileNotFoundError):
        main(["--debug", "fit", str(tmp_path / "nope"), "-o", str(tmp_path / "o.gma")])


def _write_png16(path: Path, arr: np.ndarray) -> None:
    """A 16-bit grey or RGB PNG (Pillow cannot write 16-bit RGB)."""
    import struct
    import zlib

    h, w = arr.shape[:2]
    colour = 0 if arr.ndim == 2 else 2

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    rows = arr.reshape(h, -1).astype(">u2")
    raw = b"".join(b"\x00" + row.tobytes() for row in rows)
    path.write_bytes(b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", w, h, 16, colour, 0, 0, 0))
                     + chunk(b"IDAT", zlib.compress(raw)) + chunk(b"IEND", b""))


def test_16_bit_images_read_on_the_8_bit_scale(seq_dir, tmp_path):
    """A 16-bit PNG of the same picture reads as the 8-bit one (it used to come out on a 0..257 scale)."""
    from gma.data import read_sequence

    seq = _copy_seq(seq_dir, tmp_path / "seq")
    first = sorted((seq / "images").iterdir())[0]
    img8 = iio.imread(first)[..., :3]
    _write_png16(first, img8.astype(np.uint16) * 257)
    mask = sorted((seq / "masks").iterdir())[0]
    m8 = iio.imread(mask)
    _write_png16(mask, m8.astype(np.uint16) * 257)
    s = read_sequence(seq)
    np.testing.assert_array_equal(s.image(0), img8[..., :3])
    np.testing.assert_allclose(s.mask(0), m8 / 255.0, atol=1e-6)


def test_stale_litter_is_cleaned_and_an_old_copy_restored(tmp_path):
    from gma.core.outputs import prepare_output_dir, prepare_output_file

    out = tmp_path / "a.gma"
    (tmp_path / ".a.gma.x1.tmp").write_bytes(b"half")
    prepare_output_file(out)
    assert not (tmp_path / ".a.gma.x1.tmp").exists()
    # A replacement killed between its two renames: the old sequence sits in .seq.*.old/dir.
    old = tmp_path / ".seq.k2.old" / "dir"
    old.mkdir(parents=True)
    (old / "cameras.json").write_text("{}")
    (tmp_path / ".seq.k3.partial").mkdir()
    prepare_output_dir(tmp_path / "seq", force=False)
    assert (tmp_path / "seq" / "cameras.json").is_file()
    assert not list(tmp_path.glob(".seq.*"))


def test_the_clean_up_leaves_what_a_running_process_writes(tmp_path):
    """Litter of a dead writer goes; the temporary file of a process still writing the same output stays."""
    import subprocess
    import sys

    from gma.core.outputs import prepare_output_file

    dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True,
                          text=True, check=True)
    alive = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        litter = tmp_path / f".a.gma.{dead.stdout.strip()}-x1.tmp"
        working = tmp_path / f".a.gma.{alive.pid}-x2.tmp"
        litter.write_bytes(b"half")
        working.write_bytes(b"being written")
        prepare_output_file(tmp_path / "a.gma")
        assert not litter.exists() and working.read_bytes() == b"being written"
    finally:
        alive.kill()
        alive.wait()


@pytest.mark.slow
def test_two_edits_writing_one_output_at_once_leave_one_whole_file(avatar_file, tmp_path):
    """Two ``gma edit`` processes paint different colours into the same output at the same moment: both
    finish (exit 0, or exit 2 with one line when the other's file appeared first), and the output is the
    whole file of one of them, with no temporary file left beside it."""
    import subprocess
    import sys

    from gma.avatar import Avatar

    out = tmp_path / "same.gma"
    colours = ["#ff0000", "#0000ff"]
    runs = [subprocess.Popen([sys.executable, "-m", "gma.cli", "edit", str(avatar_file), "-o", str(out),
                              "--select", "region:torso", "--paint", c, "--force"],
                             stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True) for c in colours]
    results = [(p.wait(timeout=600), p.stderr.read()) for p in runs]
    for code, err in results:
        assert code == 0 or (code == 2 and len(err.strip().splitlines()) == 1), err
        assert "Traceback" not in err
    record = Avatar.load(out).history[-1]
    assert record["op"] == "paint" and record["params"]["color"] in ([1, 0, 0], [0, 0, 1]), record
    assert sorted(p.name for p in tmp_path.iterdir()) == ["same.gma"]


def test_outputs_respect_the_umask(tmp_path):
    from gma.core.atomic import atomic_write_bytes

    old = os.umask(0o022)
    try:
        atomic_write_bytes(tmp_path / "f.bin", b"x")
    finally:
        os.umask(old)
    assert (tmp_path / "f.bin").stat().st_mode & 0o777 == 0o644


# -- a randomised sweep of gma edit's arguments ----------------------------------------------------------
# (valid, invalid) values per argument: each run draws an invalid one with probability SWEEP_BAD.
SWEEP_BAD = 0.12
# Valid selections are kept small (a paint solve costs in proportion to the faces it touches).
SWEEP_SELECTS = (["few.json", "box:front@31,12,32,13", "brush:front@32,12,1.5", "wand:front@32,20"],
                 ["region:elbows", "region:", "box:top@1,1,2,2", "box:front@1,2,3", "box:front@0,0,inf,9",
                  "brush:left@32,32,-4", "brush:front@32,32,nan", "brush:right@32,32,1e9", "wand:front@0,0",
                  "wand:front@nan,1", "wand:front", "nothing.txt", "missing.json", "selection.json"])
SWEEP_COLOURS = (["red", "#c03030", "#fff", "0.2,0.4,0.6", "black"], ["1.5,0,0", "nan,0,0", "", "#12", "chartreuse",
                                                                     "1,1"])
SWEEP_SIZES = (["0.15m", "15cm", "40px", "3m"], ["0m", "-1cm", "1e9m", "infm", "12", "m", "1e7px", "nanmm"])
SWEEP_ROTATIONS = (["0", "45", "-90", "359"], ["-720", "nan", "1e9", "-inf"])
SWEEP_VIEWS = (["front", "back", "left", "right"], ["top", ""])
SWEEP_CAMERAS = (["good.json"], ["nan_k.json", "away.json", "garbage.json", "none.json"])
SWEEP_STAMPS = (["shape:circle", "shape:ring", "shape:square"], ["shape:star", "missing.png"])
SWEEP_SHAPES = (["0.5,0.5,0.5,0.5,0.7,0.5", "0,1,0,1,0,1"], ["nan,0.5,0.5,0.5,0.5,0.5", "5,5,5,5,5,5", "0.5",
                                                           "-1,0,0,0,0,0", "a,b"])
SWEEP_EXPRESSIONS = ([",".join(["0.2"] * 52)], [",".join(["0"] * 51 + ["nan"]), "2", ",".join(["1.5"] * 52)])
SWEEP_VIEW_SIZES = (["64", "48"], ["8", "100000"])
SWEEP_RINGS = (["0", "1", "2"], ["-1", "500"])
SWEEP_TOLERANCES = (["0", "0.001"], ["5", "nan"])  # an unfitted avatar is one colour: 0.1 takes half of it


def _sweep_files(tmp: Path) -> None:
    """The cameras and selection file the sweep's arguments name."""
    from gma.core.camera import Camera

    good = Camera.look_at((0.0, -3.0, 0.9), (0.0, 0.0, 0.9), up=(0.0, 0.0, 1.0), width=64, height=64).to_json()
    (tmp / "good.json").write_text(json.dumps(good))
    (tmp / "nan_k.json").write_text(json.dumps(good | {"K": [[float("nan"), 0, 32], [0, 50, 32], [0, 0, 1]]}))
    away = Camera.look_at((0.0, 3.0, 0.9), (0.0, 6.0, 0.9), up=(0.0, 0.0, 1.0), width=64, height=64).to_json()
    (tmp / "away.json").write_text(json.dumps(away))
    (tmp / "garbage.json").write_text("{ not json")
    selection = {"format": "gma-selection", "version": 1, "body_model": "anny", "num_faces": 27420,
                 "faces": list(range(0, 2000, 100))}
    (tmp / "few.json").write_text(json.dumps(selection))
    (tmp / "selection.json").write_text(json.dumps(selection | {"num_faces": 10}))  # made on another mesh


def _sweep_argv(rng: np.random.Generator, avatar: Path, out: Path) -> list[str]:
    """One random gma edit command line: each argument valid, or (sometimes) not."""
    def pick(values) -> str:
        valid, invalid = values
        options = invalid if rng.random() < SWEEP_BAD else valid
        return str(options[rng.integers(len(options))])

    argv = ["edit", str(avatar), "-o", str(out), "--view-size", pick(SWEEP_VIEW_SIZES)]
    op = ["paint", "stamp", "body"][rng.integers(3)]
    if op == "paint":
        for _ in range(rng.integers(1, 3)):
            argv += ["--select", pick(SWEEP_SELECTS)]
        if rng.random() < 0.3:
            argv += ["--deselect", pick(SWEEP_SELECTS)]
        if rng.random() < 0.3:
            argv += [["--grow", "--shrink"][rng.integers(2)], pick(SWEEP_RINGS)]
        argv += ["--wand-tolerance", pick(SWEEP_TOLERANCES)]
        argv += ["--paint=" + pick(SWEEP_COLOURS)]
    elif op == "stamp":
        if rng.random() < 0.5:
            argv += ["--select", pick(SWEEP_SELECTS)]
        argv += ["--stamp", pick(SWEEP_STAMPS), "--size=" + pick(SWEEP_SIZES), "--rotation=" + pick(SWEEP_ROTATIONS),
                 "--color=" + pick(SWEEP_COLOURS)]
        if rng.random() < 0.3:
            argv += ["--camera", pick(SWEEP_CAMERAS)]
        else:
            argv += ["--view", pick(SWEEP_VIEWS)]
        if rng.random() < 0.2:
            argv += ["--at=" + pick((["32,32", "20,40"], ["nan,3", "1e9,1e9", "5"]))]
    else:
        if rng.random() < 0.7:
            argv += ["--shape=" + pick(SWEEP_SHAPES)]
        if rng.random() < 0.5 or len(argv) == 6:
            argv += ["--expression=" + pick(SWEEP_EXPRESSIONS)]
    return argv


def test_random_edit_arguments_exit_0_with_a_finite_avatar_or_2_with_one_line(avatar_file, tmp_path, capsys,
                                                                             monkeypatch):
    """A seeded sweep of valid and invalid gma edit arguments: every run writes a finite avatar (exit 0) or
    prints one line and writes nothing (exit 2); never a traceback, never exit 1."""
    from gma.avatar import Avatar
    from gma.core.checks import non_finite_problem

    monkeypatch.chdir(tmp_path)
    _sweep_files(tmp_path)
    rng = np.random.default_rng(65)
    out = tmp_path / "out.gma"
    codes = []
    for _ in range(30):
        argv = _sweep_argv(rng, avatar_file, out)
        try:
            code = main(argv)
        except SystemExit as exc:  # argparse
            code = exc.code
        err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
        codes.append(code)
        if code == 0:
            avatar = Avatar.load(out)  # refuses non-finite tensors itself; checked here once more
            bad = {k: p for k, v in avatar.model.state_dict().items() if (p := non_finite_problem(v))}
            assert not bad and non_finite_problem(avatar.shape) is None, (argv, bad)
            out.unlink()
        else:
            assert code == 2, (argv, code, err)
            assert len(err) == 1 and "error:" in err[0], (argv, err)
            assert not out.exists(), argv
    assert 0 in codes and 2 in codes, codes  # the sweep reaches both ends


@pytest.mark.parametrize("what", ["loss", "parameters"])
def test_a_diverging_fit_stops_with_one_line_and_resumes(what, seq_dir, tmp_path, capsys, monkeypatch):
    """A loss that turns NaN (at step 4), or parameters that do while the loss stays finite (found by the
    checkpoint of step 3), stop gma fit with one line naming the step and the last good checkpoint, which
    --resume continues from."""
    import torch

    import gma.train.trainer as trainer
    from gma.avatar import Avatar

    real_loss, real_save, calls = trainer.Trainer._loss, trainer.save_checkpoint, []

    def loss_nan_at_step_4(self, *args, **kwargs):
        loss, rec, marks = real_loss(self, *args, **kwargs)
        calls.append("loss")
        return (loss * float("nan") if calls.count("loss") == 4 else loss), rec, marks

    def save_nan_at_second_checkpoint(path, net, opt, meta):
        calls.append("save")
        if calls.count("save") == 2:
            with torch.no_grad():
                next(net.parameters()).view(-1)[0] = float("nan")
        real_save(path, net, opt, meta)

    if what == "loss":
        monkeypatch.setattr(trainer.Trainer, "_loss", loss_nan_at_step_4)
    else:
        monkeypatch.setattr(trainer, "save_checkpoint", save_nan_at_second_checkpoint)
    out = tmp_path / "o.gma"
    argv = ["fit", str(seq_dir), "-o", str(out), "--quiet", "--stage1-steps", "3", "--stage2-steps", "2",
            "--checkpoint-every", "2", "--preview-every", "0"]
    assert main(argv) == 2
    err = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    expected = ("the loss is nan at step 4", "(step 3)") if what == "loss" else ("not finite", "(step 2)")
    assert len(err) == 1 and "the fit diverged: " in err[0] and expected[0] in err[0], err
    assert f"last good checkpoint {expected[1]}" in err[0], err
    assert not out.exists() and (tmp_path / "o.fit" / "checkpoint.safetensors").is_file()
    monkeypatch.undo()
    assert main([*argv, "--resume"]) == 0
    assert Avatar.load(out).info["steps"] == 5
