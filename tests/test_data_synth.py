"""Synthetic ground truth: valid sequences, consistent cameras and ground-truth mesh, determinism."""

from __future__ import annotations

import argparse

import numpy as np
import pytest

from gma.data import read_sequence
from gma.synth.generate import SynthConfig, gt_mesh, synthesize

pytestmark = pytest.mark.gpu

SMALL = dict(
    width=64,
    height=48,
    train_frames=4,
    test_pose_frames=1,
    test_view_frames=1,
    supersample=2,
    texture_size=256,
)


@pytest.fixture(scope="module")
def anny():
    from gma.body import load_body

    return load_body("anny")


@pytest.fixture(scope="module")
def turn_seq(tmp_path_factory, gpu, anny):
    out = tmp_path_factory.mktemp("synth") / "turn"
    synthesize(out, SynthConfig(preset="turn", seed=3, **SMALL), ctx=gpu, body=anny, progress=False)
    return out


def test_sequence_is_valid(turn_seq):
    seq = read_sequence(turn_seq)
    assert len(seq) == 6 and (seq.width, seq.height) == (64, 48)
    assert (
        seq.split("train") == [0, 1, 2, 3] and seq.split("test_pose") == [4] and seq.split("test_view") == [5]
    )
    assert seq.body.model == "anny" and seq.body.arrays["facial_actions"].shape == (6, 52)
    for i in range(len(seq)):
        m = seq.mask(i)
        assert 0.05 < m.mean() < 0.6, "the person should fill a good part of the frame"
        assert ((m > 0) & (m < 1)).any(), "anti-aliased edges give soft mask values"
    assert seq.cameras.static is False and seq.cameras.K.shape == (1, 3, 3)


def test_gt_mesh_projects_into_masks(turn_seq):
    """The stored cameras, ground-truth mesh and masks agree: vertices project onto the person."""
    seq, gt = read_sequence(turn_seq), gt_mesh(turn_seq)
    v = gt["posed_vertices"]
    assert v.shape == (6, *gt["rest_vertices"].shape) and gt["faces"].max() < v.shape[1]
    assert gt["face_uvs"].shape == (len(gt["faces"]), 3, 2)
    for i in range(len(seq)):
        K, w2c = seq.cameras.frame(i)
        cam = v[i] @ w2c[:3, :3].T + w2c[:3, 3]
        assert (cam[:, 2] > 0).all()
        pix = cam @ K.T
        x, y = pix[:, 0] / pix[:, 2], pix[:, 1] / pix[:, 2]
        inside = (x >= 0) & (x < seq.width) & (y >= 0) & (y < seq.height)
        assert inside.mean() > 0.99
        # Thin parts (fingers) are sub-pixel at this size: grow the mask by one pixel before looking up.
        m = np.pad(seq.mask(i) > 0, 1)
        grown = m[1:-1, 1:-1] | m[:-2, 1:-1] | m[2:, 1:-1] | m[1:-1, :-2] | m[1:-1, 2:]
        assert grown[y[inside].astype(int), x[inside].astype(int)].mean() > 0.995


def test_garments_stand_off_the_body(turn_seq):
    gt = gt_mesh(turn_seq)
    dist = np.linalg.norm(gt["offsets"], axis=1)
    names = list(gt["garment_names"])
    labels = gt["vertex_labels"]
    assert dist[labels == names.index("skin")].max() == 0
    assert dist[labels == names.index("trousers")].max() > 0.02  # loose trouser legs
    assert dist[labels == names.index("hood")].max() > 0.03


def test_texture_has_fine_detail(turn_seq):
    import imageio.v3 as iio

    tex = iio.imread(turn_seq / "gt_texture.png").astype(np.float32)
    grad = np.abs(np.diff(tex, axis=1)).max(axis=2)
    assert (grad > 60).mean() > 0.01, "stripes, checks and prints give many sharp edges"


def test_deterministic_by_seed(tmp_path, gpu, anny, turn_seq):
    out = tmp_path / "again"
    synthesize(out, SynthConfig(preset="turn", seed=3, **SMALL), ctx=gpu, body=anny, progress=False)
    for rel in (
        "images/000000.png",
        "images/000005.png",
        "masks/000004.png",
        "gt_mesh.npz",
        "gt_texture.png",
        "body.npz",
        "cameras.json",
    ):
        assert (out / rel).read_bytes() == (turn_seq / rel).read_bytes(), rel


def test_motion_preset_and_other_seed(tmp_path, gpu, anny, turn_seq):
    out = tmp_path / "motion"
    cfg = SynthConfig(preset="motion", seed=4, **{**SMALL, "train_frames": 6, "width": 40, "height": 40})
    seq = read_sequence(synthesize(out, cfg, ctx=gpu, body=anny, progress=False).root)
    assert len(seq) == 8 and (seq.width, seq.height) == (40, 40)
    fa = seq.body.arrays["facial_actions"]
    assert fa[seq.split("train")].max() > 0  # the talking part of the clip moves the face
    assert (out / "gt_texture.png").read_bytes() != (turn_seq / "gt_texture.png").read_bytes()


def test_bad_config(tmp_path, gpu, anny):
    with pytest.raises(ValueError, match="unknown synth preset"):
        synthesize(tmp_path / "x", SynthConfig(preset="dance", **SMALL), ctx=gpu, body=anny, progress=False)
    with pytest.raises(ValueError, match="too small"):
        synthesize(tmp_path / "x", SynthConfig(width=4, height=4), ctx=gpu, body=anny, progress=False)
    assert not (tmp_path / "x").exists()


def test_cli_size_parser():
    from gma.core.args import parse_image_size as _size

    assert _size("512") == (512, 512) and _size("640x480") == (640, 480)
    with pytest.raises(argparse.ArgumentTypeError, match="N or WxH"):
        _size("big")
