"""Fitting on a tiny synthetic sequence: the two stages freeze what they should, resume after an
interruption matches an uninterrupted run, each ablation runs, eval writes its JSON and table, the
CLI is built from the config dataclasses."""

from __future__ import annotations

import json

import pytest
import torch

from gma.avatar import Avatar
from gma.train.config import preset
from gma.train.trainer import Trainer, work_dir

# Each test fits a tiny avatar for a few steps: seconds apiece on a CPU.
pytestmark = pytest.mark.slow

TINY = dict(resolution=48, checkpoint_every=1, log_every=1, preview_every=0, stage1_steps=2, stage2_steps=2,
            avatar={"feature_dim": 8, "fine_per_face": 1})


@pytest.fixture(scope="module")
def seq(tiny_sequence):
    return tiny_sequence(0)


@pytest.fixture(scope="module")
def other_seq(tiny_sequence):
    """A second person (another seed: other clothes, texture and identity)."""
    return tiny_sequence(1)


def _fit(seq, out, anny_body, gpu, resume=False, **kw):
    over = {**TINY, **kw}
    cfg = preset("quick", **over)
    return Trainer(cfg, seq, out, body=anny_body, ctx=gpu, progress=False).run(resume=resume)


def _state(avatar: Avatar) -> dict:
    return {k: v.clone() for k, v in avatar.model.state_dict().items()}


def test_two_stages_freeze(seq, anny_body, gpu, tmp_path, monkeypatch):
    cfg = preset("quick", **TINY)
    tr = Trainer(cfg, seq, tmp_path / "a.gma", body=anny_body, ctx=gpu, progress=False)
    init = _state(tr.avatar)
    seen = {}
    orig = tr._optimizer

    def spy(stage):
        opt = orig(stage)
        seen[stage.name] = {id(p) for g in opt.param_groups for p in g["params"]}
        return opt

    monkeypatch.setattr(tr, "_optimizer", spy)
    orig_save = tr.avatar.save
    snaps = {}
    from gma.train import trainer as trainer_mod

    real_ckpt = trainer_mod.save_checkpoint

    def ckpt(path, model, opt, meta):
        snaps[meta["step"]] = {k: v.clone() for k, v in model.state_dict().items()}
        real_ckpt(path, model, opt, meta)

    monkeypatch.setattr(trainer_mod, "save_checkpoint", ckpt)
    tr.run()
    del orig_save
    m = tr.model
    # Stage 1 learns geometry (f_geo, F_coarse) and texture, never F_fine (the fine layer is not shown).
    assert id(m.f_geo) in seen["stage1"] and id(m.F_fine[0].weight) not in seen["stage1"]
    # Stage 2: F_coarse and f_geo frozen, so they are bit-identical between the end of stage 1 and the end.
    assert id(m.f_geo) not in seen["stage2"] and id(m.F_fine[0].weight) in seen["stage2"]
    s1, s2 = snaps[2], snaps[4]
    assert torch.equal(s1["f_geo"], s2["f_geo"]) and torch.equal(s1["F_coarse.0.weight"], s2["F_coarse.0.weight"])
    assert not torch.equal(init["f_geo"], s1["f_geo"])
    assert not torch.equal(s1["f_tex"], s2["f_tex"]) and not torch.equal(s1["F_fine.2.weight"], s2["F_fine.2.weight"])
    d = work_dir(tmp_path / "a.gma")
    metrics = json.loads((d / "metrics.json").read_text())
    assert metrics["steps"] == 4 and len(metrics["history"]) == 4
    # The fine surfels' normal offsets are pulled toward the morphed mesh in the fine stage only.
    assert [("offset" in h) for h in metrics["history"]] == [False, False, True, True]
    assert set(metrics["ms_per_step"]) >= {"decode", "render_bwd", "optimizer"}
    assert json.loads((d / "config.json").read_text())["stage1_steps"] == 2
    assert list((d / "previews").glob("*.png"))


def test_resume_matches_uninterrupted(seq, anny_body, gpu, tmp_path, monkeypatch):
    full = _fit(seq, tmp_path / "full.gma", anny_body, gpu)
    calls = {"n": 0}
    orig = Trainer._loss

    def dying(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 4:  # killed during step 4 (after the checkpoint of step 3)
            raise KeyboardInterrupt
        return orig(self, *a, **k)

    with monkeypatch.context() as patch:
        patch.setattr(Trainer, "_loss", dying)
        with pytest.raises(KeyboardInterrupt):
            _fit(seq, tmp_path / "cut.gma", anny_body, gpu)
    assert not (tmp_path / "cut.gma").exists()
    resumed = _fit(seq, tmp_path / "cut.gma", anny_body, gpu, resume=True)
    a, b = _state(full), _state(resumed)
    for k in a:
        # GPU float atomics may sum gradients in another order, hence a tolerance rather than equality. A
        # feature that (almost) no pixel sees gets a gradient near zero whose sign can follow that order, and
        # Adam turns it into a step of a fraction of the learning rate (0.05): measured, 5 of f_tex's 219,360
        # values 3.2e-4 apart in about one run in three. A resume that lost the optimizer state or a step
        # would move all of them.
        far = ~torch.isclose(a[k], b[k], atol=1e-4, rtol=1e-3)
        assert int(far.sum()) <= max(1, a[k].numel() // 10_000), (k, int(far.sum()), a[k].numel())
        assert float((a[k] - b[k]).abs().max()) < 0.01, (k, float((a[k] - b[k]).abs().max()))


@pytest.mark.parametrize("variant", [{"training": "one_stage"}, {"avatar": {"representation": "mesh_only"}},
                                     {"avatar": {"representation": "direct", "fine_per_face": 1}}])
def test_ablations_run(seq, anny_body, gpu, tmp_path, variant):
    over = dict(variant)
    if "avatar" in over:
        over["avatar"] = {**TINY["avatar"], **over["avatar"]}
    av = _fit(seq, tmp_path / "x.gma", anny_body, gpu, **over)
    back = Avatar.load(tmp_path / "x.gma", anny_body)
    assert back.config == av.config
    n = anny_body.num_faces
    assert len(back.decode().binding) == n  # 1 surfel per face in every variant here


def test_shared_decoders_frozen(seq, anny_body, gpu, tmp_path):
    shared = _fit(seq, tmp_path / "shared.gma", anny_body, gpu)
    av = _fit(seq, tmp_path / "feat.gma", anny_body, gpu, decoders=str(tmp_path / "shared.gma"), seed=5)
    for k, v in shared.model.decoder_state().items():
        assert torch.equal(v, av.model.decoder_state()[k]), k


def test_decoders_trained_over_several_sequences(seq, other_seq, anny_body, gpu, tmp_path):
    from gma.avatar.decoders import load_decoders

    tr = Trainer(preset("quick", **TINY), [seq, other_seq], tmp_path / "shared", body=anny_body, ctx=gpu,
                 progress=False)
    init = {k: v.clone() for k, v in tr.model.decoder_state().items()}
    tr.run()
    shared = tmp_path / "shared"
    a = Avatar.load(shared / f"{seq.root.name}.gma", anny_body)
    b = Avatar.load(shared / f"{other_seq.root.name}.gma", anny_body)
    dec = load_decoders(tmp_path / "shared" / "decoders.gma", a.config)
    # One set of decoders, trained (it moved), written identically into both avatars and the decoders file.
    assert set(dec) == set(init) and any(not torch.equal(init[k], dec[k]) for k in dec)
    for k, v in dec.items():
        assert torch.equal(v, a.model.decoder_state()[k]) and torch.equal(v, b.model.decoder_state()[k]), k
    # Each person has its own features and body identity.
    assert not torch.equal(a.model.f_tex, b.model.f_tex) and not torch.equal(a.shape, b.shape)
    assert a.info["decoders_shared_with"] == [seq.root.name, other_seq.root.name]
    assert a.info["sequence"] == str(seq.root)
    # Steps take the sequences in turn.
    history = json.loads((work_dir(tmp_path / "shared") / "metrics.json").read_text())["history"]
    assert [h["subject"] for h in history] == [0, 1, 0, 1]
    # The checkpoint stores the shared decoders once and restores them into every avatar.
    again = Trainer(preset("quick", **TINY), [seq, other_seq], tmp_path / "shared", body=anny_body, ctx=gpu,
                    progress=False)
    again.run(resume=True)
    assert again.models[1].F_fine is again.models[0].F_fine
    assert torch.equal(again.models[1].f_tex, b.model.f_tex) and torch.equal(again.models[1].T_color[2].weight,
                                                                           b.model.T_color[2].weight)
    # A new fit of features only against them keeps them exactly.
    new = _fit(seq, tmp_path / "new.gma", anny_body, gpu, decoders=str(tmp_path / "shared" / "decoders.gma"))
    for k, v in dec.items():
        assert torch.equal(v, new.model.decoder_state()[k]), k


def test_decoders_errors(seq, other_seq, anny_body, gpu, tmp_path):
    from gma.avatar import AvatarFileError

    with pytest.raises(ValueError, match="names a folder"):
        Trainer(preset("quick", **TINY), [seq, other_seq], tmp_path / "x.gma", body=anny_body, ctx=gpu,
                progress=False)
    _fit(seq, tmp_path / "a.gma", anny_body, gpu)
    wider = {**TINY["avatar"], "feature_dim": 12}
    with pytest.raises(AvatarFileError, match=r"a\.gma.*feature_dim 8 vs 12"):
        _fit(seq, tmp_path / "b.gma", anny_body, gpu, decoders=str(tmp_path / "a.gma"), avatar=wider)
    (tmp_path / "junk.gma").write_bytes(b"not safetensors")
    with pytest.raises(AvatarFileError, match="junk.gma"):
        _fit(seq, tmp_path / "c.gma", anny_body, gpu, decoders=str(tmp_path / "junk.gma"))
    with pytest.raises(FileNotFoundError, match="nothere.gma"):
        _fit(seq, tmp_path / "d.gma", anny_body, gpu, decoders=str(tmp_path / "nothere.gma"))


def test_geometry_metrics(seq, anny_body, tmp_path):
    from types import SimpleNamespace

    from gma.avatar import AvatarConfig
    from gma.train.evaluate import geometry_metrics

    frames_shape = Trainer(preset("quick", **TINY), seq, tmp_path / "g.gma", body=anny_body,
                           progress=False).frames.shape
    flat = Avatar.create(AvatarConfig(**{**TINY["avatar"], "representation": "direct"}), anny_body, frames_shape)
    g = geometry_metrics(flat, seq)  # no mesh layer: exactly the bare body's error, and no roughness
    assert g["mesh_mm"] == pytest.approx(g["body_mm"]) and g["roughness_mm"] == 0
    assert geometry_metrics(flat, SimpleNamespace(root=tmp_path)) is None  # no ground truth: no figures


def test_eval_and_cli(seq, anny_body, gpu, tmp_path, capsys):
    from gma.cli import main

    _fit(seq, tmp_path / "e.gma", anny_body, gpu)
    rc = main(["eval", str(tmp_path / "e.gma"), str(seq.root), "--split", "test", "--resolution", "48",
               "--out", str(tmp_path / "ev")])
    assert rc in (0, None)
    res = json.loads((tmp_path / "ev" / "metrics_test_pose.json").read_text())
    assert len(res["frames"]) == 2 and res["mean"]["psnr"] > 10 and 0 < res["mean"]["ssim"] <= 1
    table = (tmp_path / "ev" / "metrics_test_pose.txt").read_text()
    assert "mean" in table and "region" in table
    # per region: the front-facing held-out frames show the face, the arms, the torso, the legs and the outline
    for name in ("face", "arms", "torso", "legs", "edge"):
        r = res["regions"][name]
        assert r["frames"] >= 1 and 0 < r["psnr"] < 99 and 0 < r["opacity"] <= 1 and -1 <= r["ssim"] <= 1
    assert set(res["frames"][0]["regions"]) == {"rest", "face", "hands", "arms", "torso", "legs", "edge"}
    assert res["worst"]["frames"] and res["worst"]["psnr_bbox"] <= res["mean"]["psnr_bbox"] + 1e-9
    assert list((tmp_path / "ev").glob("test_pose_*.png"))
    # synthetic sequences carry the true clothed mesh: the mesh layer is scored against it
    geometry = json.loads((tmp_path / "ev" / "geometry.json").read_text())
    assert geometry["body_clothed_mm"] > geometry["body_mm"] > 0 and geometry["gt_roughness_mm"] > 0
    # fit's options come from the dataclasses, nested ones with a dotted prefix
    import argparse

    from gma.commands import fit

    p = argparse.ArgumentParser()
    fit.register(p.add_subparsers())
    help_text = p._subparsers._group_actions[0].choices["fit"].format_help()
    assert "--stage1-steps" in help_text and "--weights2.lpips" in help_text and "--avatar.fine-per-face" in help_text
