"""The left-right symmetry prior (``gma fit --symmetry``): the mirror map of the body's faces, which
faces it pulls (those the training cameras show less than their mirror), the direction of its pull,
and a fit that uses it."""

from __future__ import annotations

import json

import pytest
import torch

from gma.body.geometry import face_centers, face_normals, mirror_faces
from gma.train.data import FrameSet
from gma.train.symmetry import SymmetryPrior, coverage_weights, face_coverage


def _rest(anny_body) -> torch.Tensor:
    params = anny_body.check_params({})
    return anny_body.rest_vertices(params).float(), anny_body.bone_transforms(params).float()


def _frames_from(anny_body, eyes: list[tuple[float, float, float]]) -> FrameSet:
    """Rest-pose frames seen from cameras at ``eyes`` (only their positions matter to the coverage)."""
    rest, bones = _rest(anny_body)
    w2c = torch.eye(4).repeat(len(eyes), 1, 1)
    w2c[:, :3, 3] = -torch.tensor(eyes)  # rotation I: eye = -R^T t
    t = len(eyes)
    return FrameSet(images=torch.zeros(t, 8, 8, 3), masks=torch.zeros(t, 8, 8, 1), K=torch.eye(3).repeat(t, 1, 1),
                    w2c=w2c, rest=rest.expand(t, -1, -1), bones=bones.expand(t, -1, -1, -1),
                    indices=list(range(t)), shape=torch.zeros(1), poses=torch.zeros(t))


def test_mirror_map_of_the_body(anny_body):
    rest, _ = _rest(anny_body)
    mirror = mirror_faces(rest, anny_body.faces)
    assert torch.equal(mirror[mirror], torch.arange(anny_body.num_faces))  # an involution
    c = face_centers(rest, anny_body.faces)
    flipped = c[mirror] * torch.tensor([-1.0, 1.0, 1.0])
    assert (flipped - c).norm(dim=-1).max() < 1e-4  # metres: float32 rounding of a symmetric mesh
    lopsided = rest.clone()
    lopsided[rest[:, 0] > 0.1, 0] += 0.01  # one arm 1 cm wider
    with pytest.raises(ValueError, match="not left-right symmetric"):
        mirror_faces(lopsided, anny_body.faces)


def test_coverage_weights_on_known_values():
    coverage = torch.tensor([0.0, 0.6, 0.3, 0.3, 0.0, 0.0])
    mirror = torch.tensor([1, 0, 3, 2, 5, 4])
    w = coverage_weights(coverage, mirror)
    # never seen, mirror seen: 1; seen more than (or as much as) the mirror: 0; neither seen: 0.
    assert torch.allclose(w, torch.tensor([1.0, 0.0, 0.0, 0.0, 0.0, 0.0]))
    pair = torch.tensor([1, 0])
    # Seen a quarter as much: shortfall 0.75, past the dead zone 0.2 -> (0.75 - 0.2) / 0.8.
    assert torch.allclose(coverage_weights(torch.tensor([0.1, 0.4]), pair), torch.tensor([0.6875, 0.0]))
    assert torch.allclose(coverage_weights(torch.tensor([0.1, 0.4]), pair, dead_zone=0.0), torch.tensor([0.75, 0.0]))
    # Seen 85 % as much as the mirror: inside the dead zone, left alone.
    assert float(coverage_weights(torch.tensor([0.34, 0.4]), pair).max()) == 0.0


def test_a_camera_on_one_side_pulls_the_other_side(anny_body):
    # Cameras on the +x side of the body only: faces turned toward -x (the far side, and the inside of
    # the near arm and leg) are what the prior should fill in from their mirrors, turned toward +x.
    frames = _frames_from(anny_body, [(3.0, 1.0, 0.5), (3.0, 1.0, -0.5)])
    prior = SymmetryPrior(frames, anny_body)
    nx = face_normals(frames.rest[0], anny_body.faces)[:, 0]
    hidden, shown = nx < -0.5, nx > 0.5
    assert float(prior.weights[shown].max()) == 0.0
    assert float(prior.weights[hidden].mean()) > 0.9
    assert float(face_coverage(frames, anny_body)[shown].mean()) > 0.5
    # Seen from both sides alike, almost nothing is pulled.
    both = SymmetryPrior(_frames_from(anny_body, [(3.0, 1.0, 0.0), (-3.0, 1.0, 0.0)]), anny_body)
    assert float(both.weights.mean()) < 0.01


def test_the_pull_moves_only_the_less_seen_side(anny_body):
    frames = _frames_from(anny_body, [(3.0, 1.0, 0.0)])
    prior = SymmetryPrior(frames, anny_body)
    f_tex = torch.randn(anny_body.num_faces, 8, requires_grad=True)
    loss = prior(f_tex)
    loss.backward()
    moved = f_tex.grad.abs().sum(-1) > 0
    assert torch.equal(moved, prior.weights > 0)  # the better-seen mirror is held fixed
    # Descending the gradient brings each pulled face toward its mirror.
    toward = (f_tex.grad * (f_tex - f_tex[prior.mirror]).detach()).sum(-1)
    assert bool((toward[moved] > 0).all())


@pytest.mark.slow
def test_fit_with_the_prior(tmp_path, gpu, anny_body, monkeypatch, capsys):
    from gma.synth.generate import SynthConfig, synthesize
    from gma.train import trainer as trainer_module
    from gma.train.config import preset
    from gma.train.trainer import Trainer, work_dir

    seq = synthesize(tmp_path / "s", SynthConfig(width=64, height=64, train_frames=3, test_pose_frames=1,
                                                 test_view_frames=1, supersample=1, texture_size=256, seed=0),
                     ctx=gpu, body=anny_body, progress=False)
    tiny = dict(resolution=48, checkpoint_every=2, log_every=1, preview_every=0, stage1_steps=2, stage2_steps=2,
                avatar={"feature_dim": 8, "fine_per_face": 1})

    def history(name: str, **kw) -> list[dict]:
        Trainer(preset("quick", **{**tiny, **kw}), seq, tmp_path / f"{name}.gma", body=anny_body, ctx=gpu,
                progress=True).run()
        d = work_dir(tmp_path / f"{name}.gma")
        assert json.loads((d / "config.json").read_text())["symmetry"] == kw.get("symmetry", 1.0)
        return json.loads((d / "metrics.json").read_text())["history"]

    on = history("on")  # on by default
    assert len(on) == 4 and all(h["symmetry"] >= 0 for h in on)
    assert "[gma] symmetry prior: " in capsys.readouterr().out
    stats = json.loads((work_dir(tmp_path / "on.gma") / "metrics.json").read_text())["symmetry_prior"]["on"]
    assert 0 <= stats["faces_pulled"] <= 1 and 0 <= stats["mean_weight_pulled"] <= 1
    assert all("symmetry" not in h for h in history("off", symmetry=0.0))
    direct = {**tiny["avatar"], "representation": "direct"}  # no per-face features: nothing to pull
    assert all("symmetry" not in h for h in history("direct", avatar=direct))
    with pytest.raises(ValueError, match="symmetry"):
        preset("quick", symmetry=-1.0)

    def lopsided(frames, body):
        raise ValueError("the body mesh is not left-right symmetric about x = 0 (...)")

    # A fit checkpointed before the prior existed (its config.json has no "symmetry") resumes as it began.
    d = work_dir(tmp_path / "off.gma")
    cfg = json.loads((d / "config.json").read_text())
    del cfg["symmetry"]
    (d / "config.json").write_text(json.dumps(cfg))
    capsys.readouterr()
    Trainer(preset("quick", **tiny), seq, tmp_path / "off.gma", body=anny_body, ctx=gpu, progress=True).run(resume=True)
    assert "resuming it with {'symmetry': 0.0}" in capsys.readouterr().out
    assert json.loads((d / "config.json").read_text())["symmetry"] == 0.0
    with pytest.raises(ValueError, match="another config"):  # any other difference is still refused
        Trainer(preset("quick", **{**tiny, "seed": 3}), seq, tmp_path / "off.gma", body=anny_body, ctx=gpu,
                progress=False).run(resume=True)

    monkeypatch.setattr(trainer_module, "SymmetryPrior", lopsided)
    capsys.readouterr()
    assert all("symmetry" not in h for h in history("lopsided"))
    assert "symmetry prior skipped: the body mesh is not left-right symmetric" in capsys.readouterr().out
