"""Sequence format: round trip, atomic writes, and validation errors that name the file and problem."""

from __future__ import annotations

import json
import os

import imageio.v3 as iio
import numpy as np
import pytest

from gma.body.params import find_model_file, load_body
from gma.core.atomic import atomic_write_bytes
from gma.data import Cameras, SequenceBody, SequenceWriter, look_at, read_sequence

W, H, T = 24, 16, 3


def anny_body(t: int = T) -> SequenceBody:
    pose = np.tile(np.eye(4, dtype=np.float32), (t, 104, 1, 1))
    pose[:, 0, :3, 3] = np.arange(t)[:, None] * 0.1
    return SequenceBody("anny", {"pose": pose, "phenotype": np.full(6, 0.5, np.float32)})


def cameras(t: int = 1) -> Cameras:
    K = np.array([[20.0, 0, W / 2], [0, 20.0, H / 2], [0, 0, 1]])
    w2c = np.stack([look_at([np.sin(a) * 3, 1, np.cos(a) * 3], [0, 1, 0]) for a in np.linspace(0, 1, t)])
    return Cameras(W, H, np.tile(K, (t, 1, 1)), w2c)


def write_seq(out, t: int = T, cams: Cameras | None = None, splits=None):
    rng = np.random.default_rng(0)
    with SequenceWriter(out, W, H) as w:
        for _ in range(t):
            w.add_frame(
                rng.integers(0, 256, (H, W, 3), dtype=np.uint8), rng.random((H, W)).astype(np.float32)
            )
        w.set_cameras(cams or cameras())
        w.set_body(anny_body(t))
        if splits:
            w.set_splits(splits)
    return out


def test_round_trip(tmp_path):
    seq = read_sequence(
        write_seq(tmp_path / "s", cams=cameras(T), splits={"train": [0, 1], "test_view": [2]})
    )
    assert len(seq) == T and (seq.width, seq.height) == (W, H)
    assert seq.image(1).shape == (H, W, 3) and seq.image(1).dtype == np.uint8
    m = seq.mask(2)
    assert m.shape == (H, W) and m.dtype == np.float32 and 0 <= m.min() and m.max() <= 1
    K, w2c = seq.cameras.frame(2)
    np.testing.assert_allclose(w2c, cameras(T).w2c[2])
    assert seq.split("train") == [0, 1] and seq.split("test_view") == [2] and seq.split("test_pose") == []
    assert seq.body.model == "anny" and seq.body.frame(2)["pose"].shape == (104, 4, 4)
    assert seq.body.frame(2)["phenotype"].shape == (6,)
    assert not any(p.name.startswith(".") for p in tmp_path.iterdir())


def test_static_camera_and_default_split(tmp_path):
    seq = read_sequence(write_seq(tmp_path / "s"))
    assert seq.cameras.static and seq.split("train") == list(range(T))
    assert seq.cameras.frame(2)[1].shape == (4, 4)


def test_rgba_without_masks(tmp_path):
    out = write_seq(tmp_path / "s")
    for p in sorted((out / "images").iterdir()):
        rgb = iio.imread(p)
        iio.imwrite(p, np.dstack([rgb, np.full((H, W), 128, np.uint8)]))
    for p in (out / "masks").iterdir():
        p.unlink()
    (out / "masks").rmdir()
    seq = read_sequence(out)
    assert seq.mask_paths is None and np.allclose(seq.mask(0), 128 / 255)


def test_crash_leaves_nothing(tmp_path):
    out = tmp_path / "s"
    with pytest.raises(RuntimeError):
        with SequenceWriter(out, W, H) as w:
            w.add_frame(np.zeros((H, W, 3), np.uint8), np.zeros((H, W), np.uint8))
            raise RuntimeError("crash mid-way")
    assert list(tmp_path.iterdir()) == []


def test_invalid_sequence_is_not_written(tmp_path):
    out = tmp_path / "s"
    with pytest.raises(ValueError, match="3 frames but the sequence has 1"):
        with SequenceWriter(out, W, H) as w:
            w.add_frame(np.zeros((H, W, 3), np.uint8), np.zeros((H, W), np.uint8))
            w.set_cameras(cameras())
            w.set_body(anny_body(3))
    assert list(tmp_path.iterdir()) == []


def test_existing_output_needs_overwrite(tmp_path):
    out = write_seq(tmp_path / "s")
    with pytest.raises(FileExistsError, match="already exists"):
        SequenceWriter(out, W, H)
    with SequenceWriter(out, W, H, overwrite=True) as w:
        w.add_frame(np.zeros((H, W, 3), np.uint8), np.zeros((H, W), np.uint8))
        w.set_cameras(cameras())
        w.set_body(anny_body(1))
    assert len(read_sequence(out)) == 1


def test_atomic_file_write(tmp_path):
    p = tmp_path / "f.bin"
    atomic_write_bytes(p, b"abc")
    assert p.read_bytes() == b"abc" and os.listdir(tmp_path) == ["f.bin"]


def _edit_json(path, **changes):
    d = json.loads(path.read_text())
    d.update(changes)
    path.write_text(json.dumps(d))


def _resave_body(path, **changes):
    d = dict(np.load(path))
    d.update(changes)
    np.savez(path, **d)


# Each case breaks one thing and says which file and words the error must contain.
BAD = {
    "frame count": (
        lambda s: _resave_body(s / "body.npz", pose=np.tile(np.eye(4), (2, 104, 1, 1))),
        "body.npz",
        "2 frames but the sequence has 3",
    ),
    "image size": (
        lambda s: iio.imwrite(s / "images" / "000001.png", np.zeros((H, W + 1, 3), np.uint8)),
        "000001.png",
        "same size",
    ),
    "missing mask": (lambda s: (s / "masks" / "000002.png").unlink(), "masks", "2 masks for 3 images"),
    "no masks": (
        lambda s: [p.unlink() for p in (s / "masks").iterdir()] and (s / "masks").rmdir(),
        "masks",
        "no alpha channel",
    ),
    "camera shape": (
        lambda s: _edit_json(s / "cameras.json", K=[[1, 0], [0, 1]]),
        "cameras.json",
        "'K' has shape",
    ),
    "camera count": (
        lambda s: _edit_json(s / "cameras.json", w2c=[np.eye(4).tolist()] * 2),
        "cameras.json",
        "2 per-frame entries",
    ),
    "camera nan": (
        lambda s: _edit_json(s / "cameras.json", K=[[float("nan"), 0, 1], [0, 1, 1], [0, 0, 1]]),
        "cameras.json",
        "non-finite",
    ),
    "camera size": (
        lambda s: _edit_json(s / "cameras.json", width=W + 2),
        "cameras.json",
        "but the images are",
    ),
    "c2w scaled": (
        lambda s: _edit_json(s / "cameras.json", w2c=(np.eye(4) * [2, 2, 2, 1]).tolist()),
        "cameras.json",
        "not a proper rotation",
    ),
    "pose nan": (
        lambda s: _resave_body(
            s / "body.npz", pose=np.where(np.arange(4) == 3, np.nan, np.tile(np.eye(4), (3, 104, 1, 1)))
        ),
        "body.npz",
        "non-finite",
    ),
    "phenotype shape": (lambda s: _resave_body(s / "body.npz", phenotype=np.zeros(5)), "body.npz", "[6]"),
    "phenotype range": (
        lambda s: _resave_body(s / "body.npz", phenotype=np.full(6, 2.0)),
        "body.npz",
        "[0, 1]",
    ),
    "unknown model": (lambda s: _resave_body(s / "body.npz", model="mano"), "body.npz", "unknown body model"),
    "pickled body": (
        lambda s: np.savez(s / "body.npz", model="anny", pose=np.array([{}], dtype=object)),
        "body.npz",
        "pickled Python objects",
    ),
    "truncated body": (
        lambda s: (s / "body.npz").write_bytes(b"PK\x03\x04garbage"),
        "body.npz",
        "not a readable",
    ),
    "no body": (lambda s: (s / "body.npz").unlink(), "body.npz", "not found"),
    "split range": (
        lambda s: (s / "splits.json").write_text('{"train": [0, 7]}'),
        "splits.json",
        "outside 0..2",
    ),
    "split type": (
        lambda s: (s / "splits.json").write_text('{"train": "all"}'),
        "splits.json",
        "list of integer",
    ),
    "smplx missing": (
        lambda s: np.savez(
            s / "body.npz",
            model="smplx",
            gender="neutral",
            betas=np.zeros(10),
            global_orient=np.zeros((3, 3)),
            body_pose=np.zeros((3, 63)),
            transl=np.zeros((3, 3)),
        ),
        "body.npz",
        "smpl-x.is.tue.mpg.de",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_validation_errors(tmp_path, monkeypatch, case):
    monkeypatch.delenv("GMA_SMPLX_DIR", raising=False)
    seq = write_seq(tmp_path / "s")
    breaker, filename, words = BAD[case]
    breaker(seq)
    with pytest.raises((ValueError, FileNotFoundError)) as info:
        read_sequence(seq)
    msg = str(info.value)
    assert filename in msg and words in msg, msg


def test_smplx_body_with_model_files(tmp_path, monkeypatch):
    seq = write_seq(tmp_path / "s")
    np.savez(
        seq / "body.npz",
        model="smplx",
        gender="female",
        betas=np.zeros(10),
        global_orient=np.zeros((3, 3)),
        body_pose=np.zeros((3, 63)),
        transl=np.zeros((3, 3)),
    )
    (tmp_path / "models" / "smplx").mkdir(parents=True)
    (tmp_path / "models" / "smplx" / "SMPLX_FEMALE.npz").write_bytes(b"")
    monkeypatch.setenv("GMA_SMPLX_DIR", str(tmp_path / "models"))
    s = read_sequence(seq)
    assert s.body.gender == "female" and s.body.frame(0)["left_hand_pose"].shape == (45,)
    assert find_model_file("smplx", "female").name == "SMPLX_FEMALE.npz"
    with pytest.raises(FileNotFoundError, match="gender 'male' not found"):
        find_model_file("smplx", "male")


def test_body_subset(tmp_path):
    np.savez(
        tmp_path / "b.npz",
        model="smpl",
        gender="male",
        betas=np.zeros(10),
        global_orient=np.arange(12.0).reshape(4, 3),
        body_pose=np.zeros((4, 69)),
        transl=np.zeros((4, 3)),
    )
    b = load_body(tmp_path / "b.npz").subset([3, 1])
    assert b.num_frames == 2 and b.arrays["global_orient"][0, 0] == 9 and b.arrays["betas"].shape == (10,)
