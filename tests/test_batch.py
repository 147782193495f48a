"""``gma batch`` on a local Ray runtime: tiny synthetic people (seeds 1..3) give the same avatars and
scores as the single-person fit and evaluation; a broken person fails alone, with its error recorded; a
re-run does nothing more; a task killed midway resumes its fit from the checkpoint; shared decoders run as
two phases equal to ``gma fit A B -o DIR`` then ``gma fit C --decoders DIR/decoders.gma``. The parts that
need no Ray (names, options, summary, the missing-Ray message) are tested without it."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import signal
import sys
import threading
import time

import pytest
import torch

from gma.batch import BatchConfig, find_people
from gma.batch.cluster import import_ray
from gma.batch.runner import check_batch_folder
from gma.batch.steps import PersonJob, export_step
from gma.batch.summary import format_markdown
from gma.core.errors import GmaError, InputError, MissingFileError
from gma.train.config import preset

# The fit of tests/test_train_fit.py's TINY, with 6 steps so that a kill can land in the middle.
TINY = dict(resolution=48, checkpoint_every=1, log_every=1, preview_every=0, stage1_steps=3, stage2_steps=3,
            avatar={"feature_dim": 8, "fine_per_face": 1})
EVAL_RES = 64
STEPS = ("import", "fit", "eval", "video")


def _batch(**kw) -> BatchConfig:
    return BatchConfig(**{"steps": STEPS, "eval_resolution": EVAL_RES, "video_size": 32, "video_frames": 3, **kw})


# -- without Ray -----------------------------------------------------------------------------------------------
def test_people_are_named_after_their_inputs(tmp_path):
    for name in ("a", "b"):
        (tmp_path / name / "x").mkdir(parents=True)
        (tmp_path / name / "x" / "cameras.json").write_text("{}")
    (tmp_path / "clip.mp4").write_bytes(b"")
    people = find_people([str(tmp_path / "a" / "x"), str(tmp_path / "b" / "x"), str(tmp_path / "clip.mp4")])
    assert [(p.name, p.kind) for p in people] == [("x", "sequence"), ("x_2", "sequence"), ("clip", "video")]
    with pytest.raises(MissingFileError, match="nope"):
        find_people([str(tmp_path / "nope")])
    with pytest.raises(InputError, match="not a sequence"):
        find_people([str(tmp_path / "a")])
    with pytest.raises(InputError, match="given twice"):
        find_people([str(tmp_path / "clip.mp4"), str(tmp_path / "clip.mp4")])


def test_options_are_checked():
    with pytest.raises(InputError, match="unknown step"):
        BatchConfig(steps=("fit", "paint"))
    with pytest.raises(InputError):
        BatchConfig(gpus_per_task=-1)


def test_batch_folder_keeps_its_fit_options(tmp_path):
    fit, batch = preset("quick", **TINY), _batch()
    (tmp_path / "b" / "p").mkdir(parents=True)
    (tmp_path / "b" / "p" / "cameras.json").write_text("{}")
    people = find_people([str(tmp_path / "b" / "p")])
    out = tmp_path / "out"
    out.mkdir()
    (out / "batch.json").write_text(json.dumps({"fit": fit.to_dict(), "batch": batch.to_dict(),
                                                "people": [p.to_dict() for p in people]}))
    check_batch_folder(out, batch, fit, people)  # same options: resumable
    check_batch_folder(out, dataclasses.replace(batch, steps=("eval",), address="auto"), fit, people)
    with pytest.raises(InputError, match="other fit options"):
        check_batch_folder(out, batch, preset("quick", **{**TINY, "seed": 3}), people)
    (tmp_path / "stranger").mkdir()
    (tmp_path / "stranger" / "notes.txt").write_text("mine")
    with pytest.raises(GmaError, match="not a gma batch folder"):
        check_batch_folder(tmp_path / "stranger", batch, fit, people)


def test_summary_markdown_lists_every_person():
    rows = [{"person": "a", "status": "done", "seconds": 3.0, "novel_view_psnr": 21.234, "novel_pose_psnr": None,
             "avatar_mb": 1.9, "guessed_pct": 35.1, "resumed_from": 2, "error": None},
            {"person": "b", "status": "failed", "seconds": 0.0, "novel_view_psnr": None, "novel_pose_psnr": None,
             "avatar_mb": None, "guessed_pct": None, "resumed_from": None, "error": "fit: x|y"}]
    md = format_markdown(rows)
    assert "| a | done | 3.00 | 21.23 |" in md and "| 1.90 | 35.10 |" in md
    assert "x\\|y" in md and "1 of 2 people done" in md


def test_missing_ray_is_one_line(monkeypatch, tmp_path, capsys):
    from gma.cli import main

    monkeypatch.setitem(sys.modules, "ray", None)
    with pytest.raises(InputError, match=r"gma\[cluster\]"):
        import_ray()
    (tmp_path / "p").mkdir()
    (tmp_path / "p" / "cameras.json").write_text("{}")
    assert main(["batch", str(tmp_path / "p"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "gma[cluster]" in err[0]


def test_export_is_skipped_when_absent(monkeypatch, tmp_path):
    from gma.batch.steps import StepSkipped

    monkeypatch.setitem(sys.modules, "gma.export", None)
    job = PersonJob(_fake_person(tmp_path), tmp_path, _batch(), preset("quick", **TINY))
    with pytest.raises(StepSkipped, match="gma.export is not installed"):
        export_step(job)


def test_a_failing_step_is_recorded_not_raised(tmp_path):
    """run_person without Ray: a video that is no video fails at import, with its error and traceback in the
    status file, and the steps after it do not run."""
    from gma.batch.task import run_person

    (tmp_path / "clip.mp4").write_bytes(b"not a video")
    job = PersonJob(find_people([str(tmp_path / "clip.mp4")])[0], tmp_path / "out", _batch(steps=("import", "fit")),
                    preset("quick", **TINY))
    status = run_person(job)
    assert status["state"] == "failed" and status["error"].startswith("import: ")
    assert "Traceback" in status["traceback"] and "fit" not in status["steps"]
    assert json.loads((tmp_path / "out" / "clip" / "status.json").read_text())["state"] == "failed"


def test_a_batch_fit_fills_the_unseen_faces(tiny_sequence, tmp_path):
    """The fit step runs the same step after the fit as ``gma fit``: the avatar has its seen record and
    the fill's summary, and the status facts say how much was guessed."""
    from gma.avatar import Avatar
    from gma.batch.steps import fit_step

    shutil.copytree(tiny_sequence(1).root, tmp_path / "p1")
    job = PersonJob(find_people([str(tmp_path / "p1")])[0], tmp_path / "out", _batch(steps=("fit",)),
                    preset("quick", **TINY))
    facts = fit_step(job)
    avatar = Avatar.load(job.avatar_path)
    assert avatar.face_seen is not None and avatar.info["unseen"]["filled"] is not None
    assert facts["guessed_area"] == avatar.info["unseen"]["guessed"]["area"] > 0  # a front-facing clip


def _fake_person(tmp_path):
    (tmp_path / "s").mkdir(exist_ok=True)
    (tmp_path / "s" / "cameras.json").write_text("{}")
    return find_people([str(tmp_path / "s")])[0]


# -- on a local Ray runtime -------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def people(tmp_path_factory, tiny_sequence):
    """Three tiny synthetic people (the session's tiny sequences of seeds 1..3, copied to folders p1..p3,
    which name them) and one whose body.npz is broken."""
    root = tmp_path_factory.mktemp("people")
    for seed in (1, 2, 3):
        shutil.copytree(tiny_sequence(seed).root, root / f"p{seed}")
    shutil.copytree(root / "p3", root / "broken")
    (root / "broken" / "body.npz").write_bytes(b"not a zip")
    return {p.name: p for p in find_people([str(root / n) for n in ("p1", "p2", "p3", "broken")])}


@pytest.fixture(scope="module")
def ray_runtime():
    """One local runtime for the module (2 CPUs, no dashboard), shut down at its end."""
    ray = pytest.importorskip("ray")
    from gma.batch.cluster import runtime_env

    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False, runtime_env=runtime_env())
    yield ray
    ray.shutdown()


@pytest.fixture(scope="module")
def single(people, gpu, anny_body, tmp_path_factory):
    """What ``gma fit SEQ -o pN.gma`` and ``gma eval`` give for p1 and p2, fitted here in-process."""
    from gma.data import read_sequence
    from gma.edit.unseen import AfterFit
    from gma.train.evaluate import evaluate_splits
    from gma.train.trainer import Trainer

    root, cfg, out = tmp_path_factory.mktemp("single"), preset("quick", **TINY), {}
    for name in ("p1", "p2"):
        seq = read_sequence(people[name].source)
        av = Trainer(cfg, seq, root / f"{name}.gma", body=anny_body, ctx=gpu, progress=False,
                     finish=AfterFit(gpu)).run()
        ev = evaluate_splits(av, seq, out_dir=None, resolution=EVAL_RES, body=anny_body, ctx=gpu, report=None)
        out[name] = ({k: v.clone() for k, v in av.model.state_dict().items()}, ev["test_view"]["mean"]["psnr"])
    return out


def _same_avatar(path, state, steps: int = 6):
    """As equal as two runs of ``gma fit`` itself: lavapipe's float atomics sum gradients in a varying
    order, and Adam (eps 1e-15) turns the sign of a near-zero gradient into a full step of the learning
    rate (0.05), so a few feature entries in 10^4 differ between two identical runs, by at most one step
    per fit step; everything else agrees to 1e-4."""
    from gma.avatar import Avatar

    mine = Avatar.load(path).model.state_dict()
    for k, v in state.items():
        off = ~torch.isclose(mine[k], v, atol=1e-4, rtol=1e-3)
        assert off.float().mean() < 1e-3 and (mine[k] - v).abs().max() <= 0.05 * steps, k


@pytest.mark.slow
def test_batch_equals_single_person_and_goes_on_after_a_failure(people, ray_runtime, single, tmp_path):
    from gma.batch.runner import run_batch

    out, fit = tmp_path / "out", preset("quick", **TINY)
    # Two people beside the broken one: as many tasks as the runtime's two CPUs run at once, and one more.
    batch = [people[n] for n in ("p1", "p2", "broken")]
    rows = run_batch(batch, out, _batch(), fit, progress=False)
    by = {r["person"]: r for r in rows}
    assert [by[n]["status"] for n in ("p1", "p2", "broken")] == ["done"] * 2 + ["failed"]
    assert "body.npz" in by["broken"]["error"] and by["broken"]["error"].startswith("fit:")
    for name in ("p1", "p2"):
        _same_avatar(out / name / "avatar.gma", single[name][0])
        assert by[name]["novel_view_psnr"] == pytest.approx(single[name][1], abs=0.05)
        assert (out / name / "turntable.mp4").is_file() and (out / name / "eval" / "metrics_test_view.json").is_file()
    assert "2 of 3 people done" in (out / "summary.md").read_text()
    assert (out / "summary.csv").read_text().splitlines()[0].startswith("person,status,seconds,novel_view_psnr")
    # A re-run touches no finished person (no new run in its status) and tries the failed one again.
    run_batch(batch, out, _batch(), fit, progress=False)
    runs = {n: json.loads((out / n / "status.json").read_text())["runs"] for n in by}
    assert runs == {"p1": 1, "p2": 1, "broken": 2}


@pytest.mark.slow
def test_a_task_killed_midway_resumes(people, ray_runtime, single, tmp_path):
    from gma.batch.runner import run_batch

    out, fit = tmp_path / "out", preset("quick", **TINY)
    ckpt, status = out / "p1" / "avatar.fit" / "checkpoint.safetensors", out / "p1" / "status.json"
    first = threading.Thread(target=run_batch, args=([people["p1"]], out, _batch(steps=("fit",)), fit),
                             kwargs={"progress": False})
    first.start()
    deadline = time.monotonic() + 240
    while not ckpt.is_file() and time.monotonic() < deadline:
        time.sleep(0.02)
    assert ckpt.is_file(), "the fit never wrote a checkpoint"
    os.kill(json.loads(status.read_text())["pid"], signal.SIGKILL)  # the worker process, mid-fit
    first.join(120)
    killed = json.loads(status.read_text())
    assert killed["state"] == "failed" and "worker lost" in killed["error"]
    assert not (out / "p1" / "avatar.gma").exists()

    rows = run_batch([people["p1"]], out, _batch(steps=("fit", "eval")), fit, progress=False)
    assert rows[0]["status"] == "done" and 0 < rows[0]["resumed_from"] < 6
    _same_avatar(out / "p1" / "avatar.gma", single["p1"][0])


@pytest.mark.slow
def test_shared_decoders_in_two_phases(people, ray_runtime, gpu, anny_body, tmp_path):
    from gma.batch.runner import run_batch
    from gma.batch.task import phase1_config
    from gma.data import read_sequence
    from gma.edit.unseen import AfterFit
    from gma.train.trainer import Trainer

    fit = preset("quick", **TINY)
    trio = [people[n] for n in ("p1", "p2", "p3")]
    rows = run_batch(trio, tmp_path / "out", _batch(steps=("fit",), train_decoders=2), fit, progress=False)
    assert [r["status"] for r in rows] == ["done"] * 3
    # The same as: gma fit p1 p2 -o ref (twice the steps); gma fit p3 -o p3.gma --decoders ref/decoders.gma
    seqs = [read_sequence(p.source) for p in trio]
    Trainer(phase1_config(fit, 2), seqs[:2], tmp_path / "ref", body=anny_body, ctx=gpu, progress=False,
            finish=AfterFit(gpu)).run()
    own = dataclasses.replace(fit, decoders=str(tmp_path / "ref" / "decoders.gma"))
    p3 = Trainer(own, seqs[2], tmp_path / "p3.gma", body=anny_body, ctx=gpu, progress=False,
                 finish=AfterFit(gpu)).run()
    from gma.avatar import Avatar

    for name in ("p1", "p2"):
        _same_avatar(tmp_path / "out" / name / "avatar.gma",
                     Avatar.load(tmp_path / "ref" / f"{name}.gma").model.state_dict(), steps=12)
    _same_avatar(tmp_path / "out" / "p3" / "avatar.gma", p3.model.state_dict())
    status = json.loads((tmp_path / "out" / "p3" / "status.json").read_text())
    assert status["steps"]["fit"]["decoders"].endswith("decoders.gma")
    assert "Shared decoders (phase 1, p1,p2): done" in (tmp_path / "out" / "summary.md").read_text()


@pytest.mark.slow
def test_decoders_from_one_person(people, ray_runtime, tmp_path):
    """One person's own fit is the decoder set: phase 1 is an ordinary avatar, which --decoders takes."""
    from gma.batch.runner import run_batch

    out = tmp_path / "out"
    rows = run_batch([people["p1"], people["p2"]], out, _batch(steps=("fit",), train_decoders=1),
                     preset("quick", **TINY), progress=False)
    assert [r["status"] for r in rows] == ["done", "done"]
    assert (out / "_shared" / "p1.gma").is_file()
    fit = json.loads((out / "p2" / "status.json").read_text())["steps"]["fit"]
    assert fit["decoders"] == str(out / "_shared" / "p1.gma")


@pytest.mark.slow
def test_failed_phase1_fails_everyone_with_its_reason(people, ray_runtime, tmp_path):
    from gma.batch.runner import run_batch

    rows = run_batch([people["broken"], people["p1"], people["p2"]], tmp_path / "out",
                     _batch(steps=("fit",), train_decoders=2), preset("quick", **TINY), progress=False)
    assert [r["status"] for r in rows] == ["failed"] * 3
    assert all(r["error"].startswith("shared decoders:") and "body.npz" in r["error"] for r in rows)


@pytest.mark.slow
def test_an_interrupted_command_resumes(people, ray_runtime, tmp_path):
    """``gma batch`` (joining the test's runtime with --address) stopped by Ctrl-C mid-fit exits 130 and
    leaves the person running; the same batch again resumes the fit from its checkpoint. Ctrl-C is sent as
    soon as the first step's checkpoint exists, so 2 x 25 small steps leave it inside the fit on a quiet
    machine too; that a resumed fit equals an uninterrupted one is checked by
    test_a_task_killed_midway_resumes."""
    import subprocess
    from pathlib import Path

    from gma.batch.runner import run_batch

    out = tmp_path / "out"
    repo = Path(__file__).resolve().parents[1]
    options = ["--resolution", "32", "--checkpoint-every", "1", "--log-every", "1", "--preview-every", "0",
               "--stage1-steps", "25", "--stage2-steps", "25", "--avatar.feature-dim", "8",
               "--avatar.fine-per-face", "1"]
    cmd = [sys.executable, "-m", "gma.cli", "batch", people["p1"].source, "-o", str(out), "--steps", "fit", "--quiet",
           "--address", ray_runtime.get_runtime_context().gcs_address, *options]
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(repo), os.environ.get("PYTHONPATH", "")])}
    # Ctrl-C in a terminal reaches a process whose SIGINT is at its default; a suite started in the
    # background of a non-interactive shell (`make test &`) has it ignored, and children inherit that.
    proc = subprocess.Popen(cmd, cwd=repo, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    ckpt = out / "p1" / "avatar.fit" / "checkpoint.safetensors"
    deadline = time.monotonic() + 240
    while not ckpt.is_file() and proc.poll() is None and time.monotonic() < deadline:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    output, _ = proc.communicate(timeout=120)
    assert proc.returncode == 130, output[-2000:]
    assert json.loads((out / "p1" / "status.json").read_text())["state"] == "running"

    long_fit = preset("quick", **{**TINY, "resolution": 32, "stage1_steps": 25, "stage2_steps": 25})
    rows = run_batch([people["p1"]], out, _batch(steps=("fit",)), long_fit, progress=False)
    assert rows[0]["status"] == "done" and 0 < rows[0]["resumed_from"] < 50
