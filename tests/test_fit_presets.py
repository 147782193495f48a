"""The presets and what the standard one rests on: a stage 1 at a lower resolution than stage 2 (frames
resized with their intrinsics), and gma fit's choice of preset by where a sequence came from."""

from __future__ import annotations

import pytest
import torch

from gma.train.config import FitConfig, preset

# -- fast ----------------------------------------------------------------------------------------------


def test_standard_preset_trains_the_texture_at_384_and_the_geometry_lower():
    cfg = preset("standard")
    assert cfg.resolution >= 384 and 0 < cfg.stage1_resolution < cfg.resolution
    assert cfg.unmix_background and cfg.preset == "standard"
    assert preset("standard", resolution=256).resolution == 256     # options still override it
    with pytest.raises(ValueError, match="--stage1-resolution"):
        FitConfig(stage1_resolution=4)
    # a fit asked for a lower --resolution than the preset's stage 1 runs both stages at it
    from gma.train.trainer import plan_stages

    assert [s.resolution for s in plan_stages(preset("standard", resolution=128))] == [128, 128]
    assert [s.resolution for s in plan_stages(preset("standard"))] == [192, 384]


def test_gma_fit_picks_standard_for_imported_videos(tmp_path):
    from gma.commands.fit import default_preset

    video, synth = tmp_path / "v", tmp_path / "s"
    video.mkdir()
    synth.mkdir()
    (video / "video_report.json").write_text("{}")
    assert default_preset([str(video)]) == "standard"
    assert default_preset([str(synth)]) == "quick"
    assert default_preset([str(video), str(synth)]) == "quick"


def _frames(h: int, w: int):
    from gma.train.data import FrameSet

    g = torch.Generator().manual_seed(0)
    K = torch.tensor([[1.2 * w, 0, w / 2], [0, 1.2 * w, h / 2], [0, 0, 1]])[None]
    return FrameSet(torch.rand(1, h, w, 3, generator=g), torch.ones(1, h, w, 1), K, torch.eye(4)[None],
                    torch.zeros(1, 5, 3), torch.eye(4)[None, None], [0], torch.zeros(3), torch.eye(4)[None, None])


def test_resized_frames_keep_the_camera():
    frames = _frames(64, 48)
    small = frames.resized(32)
    assert small.images.shape == (1, 32, 24, 3) and small.masks.shape == (1, 32, 24, 1)
    # a point in the image's corner-to-corner frame stays at the same place relative to the image
    p = torch.tensor([0.1, -0.2, 2.0])
    for f in (frames, small):
        uv = (f.K[0] @ p)[:2] / p[2]
        h, w = f.images.shape[1:3]
        rel = uv / torch.tensor([w, h])
        torch.testing.assert_close(rel, (frames.K[0] @ p)[:2] / p[2] / torch.tensor([48.0, 64.0]))
    torch.testing.assert_close(small.images.mean(), frames.images.mean())  # area: the mean is kept
    assert frames.resized(64) is frames and frames.resized(100) is frames   # never upscaled


# -- slow: on lavapipe ---------------------------------------------------------------------------------


@pytest.mark.slow
def test_stage1_renders_at_its_own_resolution(tiny_sequence, anny_body, gpu, tmp_path, monkeypatch):
    import gma.train.trainer as trainer_module
    from gma.train.trainer import Trainer

    seq = tiny_sequence(0)
    cfg = preset("quick", resolution=48, stage1_resolution=24, stage1_steps=2, stage2_steps=2, preview_every=0,
                 fill_unseen=False, colour_edge=1.0, avatar={"feature_dim": 8, "fine_per_face": 1},
                 pose={"refine": "on", "align": 1})
    sizes = []
    real = trainer_module.render_frame

    def spy(decoded, body, frames, *a, **k):
        sizes.append(tuple(frames.images.shape[1:3]))
        return real(decoded, body, frames, *a, **k)

    monkeypatch.setattr(trainer_module, "render_frame", spy)
    trainer = Trainer(cfg, seq, tmp_path / "a.gma", body=anny_body, ctx=gpu, progress=False)
    trainer.run()
    assert sizes == [(24, 24)] * 2 + [(48, 48)] * 3, sizes  # two steps of each stage, the last preview
    assert {r: v[1].shape[1] for r, v in trainer.subjects[0].views.items()} == {24: 24, 48: 48}
