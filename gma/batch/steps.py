"""The steps of one person, each a thin call into the single-person library (the same calls as ``gma import
video``, ``gma fit``, ``gma eval``, ``gma export`` and ``gma demo``'s turntable), so that a batch gives the
same results as those commands for the same inputs and options.

A step is ``fn(job: PersonJob) -> dict`` of facts for the status file; it raises :class:`StepSkipped`
when it has nothing to do (a sequence needs no import; no export module installed). New steps go into
:data:`STEPS` (and :data:`gma.batch.config.ALL_STEPS`)."""

from __future__ import annotations

import importlib
import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from safetensors import safe_open

from gma.avatar import Avatar
from gma.avatar.gpu import AvatarRenderer
from gma.avatar.video import render_turntable, sequence_camera, write_video
from gma.batch.config import BatchConfig, Person
from gma.body import load_body
from gma.core.atomic import atomic_write_bytes
from gma.data import read_sequence
from gma.edit.unseen import AfterFit
from gma.gpu import get_context
from gma.train.config import FitConfig
from gma.train.evaluate import EVAL_SPLITS, evaluate_splits
from gma.train.outputs import CHECKPOINT_NAME, prepare_fit_outputs
from gma.train.trainer import Trainer, work_dir
from gma.video import VideoImportConfig, estimate_sequence

__all__ = ["OUTPUTS", "STEPS", "PersonJob", "StepSkipped", "guessed_facts", "worker_body", "worker_context"]


class StepSkipped(Exception):
    """A step with nothing to do here; its message is recorded as the reason."""


@dataclass
class PersonJob:
    """What a step needs: who, where, and how."""

    person: Person
    out: Path  # the batch folder
    batch: BatchConfig
    fit: FitConfig  # decoders set for phase 2 of a shared-decoder batch
    shared_avatar: str | None = None  # phase 1 fitted this person already (with the shared decoders)

    @property
    def folder(self) -> Path:
        return self.person.folder(self.out)

    @property
    def avatar_path(self) -> Path:
        return self.person.avatar(self.out)

    def sequence(self):
        return read_sequence(self.person.sequence(self.out))


def worker_body(name: str = "anny"):
    """The body model, loaded once per worker process (``load_body`` caches it) and kept for later people."""
    return load_body(name)  # created once per worker process and cached there


def worker_context():
    """The worker's GPU context, created on first use and kept for later people."""
    return get_context()


def import_step(job: PersonJob) -> dict:
    """A video becomes ``<name>/sequence`` as ``gma import video`` makes it (masks, camera and body
    estimated; its resumable work in ``sequence.work/``). A sequence is used where it is."""
    if job.person.kind == "sequence":
        raise StepSkipped("already a sequence")
    target = job.person.sequence(job.out)
    seq, report = estimate_sequence(job.person.source, target, config=VideoImportConfig(), overwrite=True,
                                    progress=False)
    return {"frames": len(seq), "mask_iou": report.get("mask_iou_mean")}


def _checkpoint_step(checkpoint: Path) -> int:
    """The step an interrupted fit's checkpoint holds (0 when none or unreadable)."""
    try:
        with safe_open(str(checkpoint), "pt") as f:
            return int(json.loads(f.metadata()["meta"])["step"])
    except Exception:  # a damaged checkpoint: the trainer reports it by name
        return 0


def fit_step(job: PersonJob) -> dict:
    """``gma fit SEQ -o avatar.gma --resume`` (the fill of the unseen faces included; with ``--decoders`` in
    phase 2 of a shared-decoder batch), or, for a person of the decoder subset, the avatar that phase 1
    fitted (and filled)."""
    out = job.avatar_path
    if job.shared_avatar is not None:
        atomic_write_bytes(out, Path(job.shared_avatar).read_bytes())
        return {"decoders": "trained here (phase 1)", "avatar_bytes": out.stat().st_size,
                **guessed_facts(_avatar(job))}
    seq = job.sequence()
    resumed = _checkpoint_step(work_dir(out) / CHECKPOINT_NAME)
    prepare_fit_outputs(out, [seq], resume=True)  # a batch always continues what an earlier run began
    trainer = Trainer(job.fit, seq, out, body=worker_body(job.fit.avatar.body), ctx=worker_context(),
                      progress=False, finish=AfterFit(worker_context()))
    avatar = trainer.run(resume=True)
    return {"steps": avatar.info["steps"], "resumed_from": resumed, "fit_seconds": avatar.info["fit_seconds"],
            "decoders": job.fit.decoders or "own", "avatar_bytes": out.stat().st_size, **guessed_facts(avatar)}


def guessed_facts(avatar) -> dict:
    """How much of a fitted avatar the frames never showed and the fill guessed (``gma fit`` prints the
    same): shares of the body surface and of the faces; nothing for an avatar fitted with
    ``--fill-unseen false``."""
    unseen = avatar.info.get("unseen")
    if not unseen:
        return {}
    return {"guessed_area": unseen["guessed"]["area"], "guessed_faces": unseen["guessed"]["faces"]}


def _avatar(job: PersonJob):
    return Avatar.load(job.avatar_path, body=worker_body(job.fit.avatar.body))


def eval_step(job: PersonJob) -> dict:
    """``gma eval avatar.gma SEQ --out <name>/eval``: the held-out splits (novel poses, novel views)."""
    seq = job.sequence()
    splits = [s for s in EVAL_SPLITS if seq.split(s)]
    if not splits:
        raise StepSkipped("the sequence has no test_pose or test_view split")
    avatar = _avatar(job)
    results = evaluate_splits(avatar, seq, splits, job.folder / "eval", job.batch.eval_resolution,
                              job.fit.background, body=worker_body(avatar.body_name), ctx=worker_context(),
                              report=None)
    facts = {f"{s}_{k}": v for s in splits for k, v in results[s]["mean"].items()}
    if results["geometry"] is not None:
        facts["mesh_mm"] = results["geometry"]["mesh_mm"]
    return facts


def export_step(job: PersonJob) -> dict:
    """``gma export avatar.gma <name>/avatar.ply`` (canonical pose, splat PLY), when ``gma.export`` is
    installed; it comes from another branch, so its absence skips the step instead of failing it."""
    try:
        export = importlib.import_module("gma.export")
    except ImportError:
        raise StepSkipped("gma.export is not installed in this GMA (no 'gma export' command)") from None
    avatar = _avatar(job)
    body = worker_body(avatar.body_name)
    pose = export.export_poses(avatar, body, "canonical")[0]
    path = job.folder / "avatar.ply"
    export.write_splats(path, export.posed_splats(avatar, body, pose.params), job.batch.export_format)
    return {"file": path.name, "bytes": path.stat().st_size}


def video_step(job: PersonJob) -> dict:
    """A turntable video of the avatar in its canonical pose, as ``gma demo`` makes it: the camera of the
    first training frame, turned about the vertical axis."""
    avatar, seq = _avatar(job), job.sequence()
    body, ctx, size = worker_body(avatar.body_name), worker_context(), job.batch.video_size
    renderer = AvatarRenderer(ctx, avatar, body)
    K, w2c = sequence_camera(seq, size)
    canon, bg = body.canonical_params(avatar.shape), (job.fit.background,) * 3
    frames = render_turntable(renderer, canon, K, w2c, size, job.batch.video_frames, bg)
    path = write_video(job.folder / "turntable.mp4", frames)
    return {"file": path.name, "frames": len(frames)}


STEPS: dict[str, Callable[[PersonJob], dict]] = {"import": import_step, "fit": fit_step, "eval": eval_step,
                                                  "export": export_step, "video": video_step}

# What a finished step left behind, beyond the file its facts name: a step recorded as done whose output
# is gone runs again.
OUTPUTS: dict[str, Callable[[PersonJob], Path]] = {
    "import": lambda job: job.person.sequence(job.out) / "cameras.json",
    "fit": lambda job: job.avatar_path,
    "eval": lambda job: job.folder / "eval",
}
