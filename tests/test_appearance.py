"""What a frame owes to the camera, kept out of the avatar (gma.train.appearance): the colour loss weighs
pixels 0 outside the person's mask and rises over the edge band; per-frame colour transforms start at
identity, leave the background alone, are learnt in a fit (recorded, checkpointed, resumable from a fit
made before they existed) and fitted at test time beside the poses."""

from __future__ import annotations

import json
import shutil
from types import SimpleNamespace

import pytest
import torch

from gma.train.appearance import FrameColour, colour_wanted, colour_weights, unmix_background, weighted_picture_loss
from gma.train.config import FitConfig, FrameColourConfig, preset
from gma.train.losses import picture_loss

# -- fast ----------------------------------------------------------------------------------------------


def _square_mask(size: int = 21, half: int = 6) -> torch.Tensor:
    mask = torch.zeros(1, size, size, 1)
    c = size // 2
    mask[0, c - half:c + half + 1, c - half:c + half + 1] = 1.0
    return mask  # [1, H, W, 1]


def test_colour_weights_rise_from_the_mask_edge():
    mask = _square_mask()
    w = colour_weights(mask, 3.0)[0, ..., 0]
    c = 10
    assert w.shape == mask.shape[1:3]
    assert float(w[mask[0, ..., 0] < 0.5].abs().max()) == 0.0          # nothing outside the person
    assert float(w[c, c]) == 1.0                                       # deep inside: full weight
    assert float(w[c, c + 6]) == pytest.approx(1 / 3)                  # the boundary's inner row
    assert float(w[c, c + 5]) == pytest.approx(2 / 3)
    assert float(w[c, c + 4]) == 1.0
    assert torch.equal(colour_weights(mask, 0.0), torch.ones_like(mask))  # 0: the whole image


def test_weighted_picture_loss():
    g = torch.Generator().manual_seed(0)
    a, b = torch.rand(16, 16, 3, generator=g), torch.rand(16, 16, 3, generator=g)
    l1, dssim = weighted_picture_loss(a, b, torch.ones(16, 16, 1))
    want = picture_loss(a, b)
    assert float(l1) == pytest.approx(float(want[0])) and float(dssim) == pytest.approx(float(want[1]), abs=1e-6)
    # with weight 0 on the left half, what the render shows there does not change the loss
    w = torch.ones(16, 16, 1)
    w[:, :8] = 0
    other = a.clone()
    other[:, :2] = 0.0  # far enough from the right half that SSIM's window does not reach it
    for x, y in zip(weighted_picture_loss(a, b, w), weighted_picture_loss(other, b, w), strict=True):
        assert float(x) == pytest.approx(float(y), abs=1e-7)
    assert float(weighted_picture_loss(a, b, w)[0]) < float(want[0])


def test_frame_colour_is_identity_at_first_and_leaves_the_background():
    colour = FrameColour(2)
    color = torch.rand(8, 8, 3)
    alpha = torch.zeros(8, 8, 1)
    alpha[2:6, 2:6] = 1.0
    color = color * alpha + 0.5 * (1 - alpha)
    torch.testing.assert_close(colour.apply(1, color, alpha, 0.5), color)
    assert float(colour.regulariser(0).detach()) == 0.0
    with torch.no_grad():
        colour.gain[1].fill_(-0.5)
        colour.offset[1].fill_(0.1)
    out = colour.apply(1, color, alpha, 0.5)
    torch.testing.assert_close(out[alpha[..., 0] == 0], color[alpha[..., 0] == 0])   # background untouched
    inside = alpha[..., 0] == 1
    torch.testing.assert_close(out[inside], 0.5 * color[inside] + 0.1)
    torch.testing.assert_close(colour.apply(0, color, alpha, 0.5), color)            # frames are separate
    assert float(colour.regulariser(1).detach()) == pytest.approx(3 * 0.25 + 3 * 0.01)
    assert colour.summary()["max_gain"] == pytest.approx(0.5)


def test_colour_wanted_follows_the_video_marker(tmp_path):
    seq = SimpleNamespace(root=tmp_path)
    assert not colour_wanted(FrameColourConfig(), seq)
    (tmp_path / "video_report.json").write_text("{}")
    assert colour_wanted(FrameColourConfig(), seq)
    assert not colour_wanted(FrameColourConfig(refine="off"), seq)
    assert colour_wanted(FrameColourConfig(refine="on"), SimpleNamespace(root=tmp_path / "x"))


def test_colour_options_are_checked():
    with pytest.raises(ValueError, match="--colour.refine"):
        FrameColourConfig(refine="maybe")
    with pytest.raises(ValueError, match="--colour-edge"):
        FitConfig(colour_edge=-1.0)
    with pytest.raises(ValueError, match="--colour.prior"):
        preset("quick", colour={"prior": float("nan")})


# -- slow: on lavapipe ---------------------------------------------------------------------------------

TINY = dict(resolution=32, checkpoint_every=1, log_every=1, preview_every=0, stage1_steps=3, stage2_steps=2,
            fill_unseen=False, avatar={"feature_dim": 8, "fine_per_face": 1})


@pytest.fixture(scope="module")
def seq(tiny_sequence):
    return tiny_sequence(0)


def _fit(s, out, anny_body, gpu, resume=False, progress=False, **kw):
    from gma.train.trainer import Trainer

    cfg = preset("quick", **{**TINY, "pose": {"refine": "off"}, "colour": {"refine": "on"}, "colour_edge": 2.0, **kw})
    trainer = Trainer(cfg, s, out, body=anny_body, ctx=gpu, progress=progress)
    return trainer, trainer.run(resume=resume)


@pytest.mark.slow
def test_fit_learns_frame_colours_and_records_them(seq, anny_body, gpu, tmp_path):
    from safetensors import safe_open

    from gma.train.trainer import work_dir

    trainer, avatar = _fit(seq, tmp_path / "a.gma", anny_body, gpu)
    colours = trainer.colour_sets[0]
    assert len(colours) == len(trainer.frames)
    assert any(float(g.detach().abs().max()) > 0 for g in colours.gain)          # they took part
    assert avatar.info["frame_colour"] == colours.summary()
    metrics = json.loads((work_dir(tmp_path / "a.gma") / "metrics.json").read_text())
    assert "frame_colour" in metrics and "colour_reg" in metrics["history"][-1]
    # the transforms are in the checkpoint (a resumed fit continues with them)
    with safe_open(str(work_dir(tmp_path / "a.gma") / "checkpoint.safetensors"), "pt") as f:
        assert any(k.startswith("model.colours.") for k in f.keys())


@pytest.mark.slow
def test_fit_from_before_the_colour_options_resumes_without_them(seq, anny_body, gpu, tmp_path, capsys):
    kw = dict(colour={"refine": "off"}, colour_edge=0.0)
    _fit(seq, tmp_path / "old.gma", anny_body, gpu, stage2_steps=0, **kw)
    from gma.train.trainer import work_dir

    d = work_dir(tmp_path / "old.gma")
    cfg = json.loads((d / "config.json").read_text())
    del cfg["colour"], cfg["colour_edge"]
    (d / "config.json").write_text(json.dumps(cfg))
    ckpt = d / "checkpoint.safetensors"
    shutil.copy(ckpt, tmp_path / "kept.safetensors")
    capsys.readouterr()
    trainer, _ = _fit(seq, tmp_path / "old.gma", anny_body, gpu, resume=True, progress=True, stage2_steps=0)
    assert "colour_edge" in capsys.readouterr().out
    assert trainer.cfg.colour.refine == "off" and trainer.cfg.colour_edge == 0.0
    assert not trainer.colour_sets


@pytest.mark.slow
def test_test_time_colour_fitting_recovers_an_exposure_change(seq, anny_body, gpu):
    """A frame whose picture is the avatar's own render, darkened by 30 %: fitting its colour transform
    beside its pose brings the render to the picture, which the pose alone cannot."""
    from gma.avatar.avatar import Avatar
    from gma.avatar.config import AvatarConfig
    from gma.train.data import load_frames
    from gma.train.pose_refine import PoseRefineConfig, refine_frozen
    from gma.train.render_step import render_frame

    avatar = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1), anny_body, seed=0)
    with torch.no_grad():
        avatar.model.T_color[2].bias.copy_(torch.tensor([1.5, 0.0, -1.0]))  # an orange person, not grey
    decoded = avatar.decode()
    frames = load_frames(seq, anny_body, "train", 32, max_frames=1)
    with torch.no_grad():
        out, _ = render_frame(decoded, anny_body, frames, 0, 0.0, gpu)
    frames.images[0] = 0.7 * out.color
    frames.masks[0] = out.alpha
    colour = FrameColour(1)
    refine_frozen(decoded, anny_body, frames, 30, PoseRefineConfig(), 0.0, gpu, colour=colour,
                  colour_cfg=FrameColourConfig(lr=0.1))
    with torch.no_grad():
        shown = colour.apply(0, out.color, out.alpha, 0.0)
    before = float((out.color - frames.images[0]).abs().mean())
    after = float((shown - frames.images[0]).abs().mean())
    assert after < 0.3 * before, (before, after)
    assert float(colour.gain[0].detach().mean()) < -0.05  # darker, through the gain (and the offset)


def test_unmix_background_takes_a_green_screen_out_of_soft_edges():
    person, green = torch.tensor([0.9, 0.1, 0.1]), torch.tensor([0.1, 0.8, 0.2])
    m = torch.zeros(1, 24, 24, 1)
    m[0, 6:18, 6:18] = 1.0
    m[0, 6:18, 5] = 0.5      # a soft left edge
    m[0, 6:18, 18] = 0.25    # and a softer right edge
    images = m * person + (1 - m) * green
    out = unmix_background(images, m)
    soft = (m[..., 0] > 0) & (m[..., 0] < 1)
    torch.testing.assert_close(out[soft], person.expand(int(soft.sum()), 3), atol=1e-5, rtol=0)
    torch.testing.assert_close(out[~soft], images[~soft])                 # the rest as it was
    target = out * m + 0.5 * (1 - m)                                      # what the fit compares with
    assert float(target[0, 10, 5, 1]) == pytest.approx(0.5 * 0.1 + 0.5 * 0.5)   # no green left in it
    # a frame the person fills has no background to estimate: left alone
    x = torch.rand(1, 8, 8, 3)
    torch.testing.assert_close(unmix_background(x, torch.full((1, 8, 8, 1), 0.7)), x)
