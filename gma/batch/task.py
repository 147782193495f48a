"""One person's task and the shared decoders' task: plain functions (no Ray here) that the runner sends
to Ray workers, and that tests and a debugger can call directly.

A task never raises for a problem with its person: it records the error in the status file and returns
it, so that one bad video does not stop a batch of a thousand."""

from __future__ import annotations

import dataclasses
import time
import traceback
from pathlib import Path

from gma.batch.status import TaskStatus
from gma.batch.steps import OUTPUTS, STEPS, PersonJob, StepSkipped, worker_body, worker_context
from gma.edit.unseen import AfterFit
from gma.train.config import FitConfig
from gma.train.outputs import prepare_fit_outputs
from gma.train.trainer import Trainer, subject_outputs

__all__ = ["SHARED_DIR", "is_finished", "phase1_config", "run_person", "run_shared_decoders", "shared_paths"]

SHARED_DIR = "_shared"  # OUT/_shared/: phase 1 of a shared-decoder batch ("_" is never a person's name)


def _step_current(job: PersonJob, status: TaskStatus, step: str) -> bool:
    """Was ``step`` finished by an earlier run, and is what it wrote still there?"""
    if not status.step_done(step):
        return False
    rec = status.data["steps"][step]
    if rec["state"] == "skipped":
        return True
    out = OUTPUTS.get(step)
    files = ([out(job)] if out else []) + ([job.folder / rec["file"]] if "file" in rec else [])
    return all(f.exists() for f in files)


def is_finished(job: PersonJob) -> bool:
    """Are all of the job's steps recorded as done, with their outputs in place? (No task needed then.)"""
    status = TaskStatus(job.folder)  # an empty one when there is no file
    return all(_step_current(job, status, s) for s in job.batch.steps)


def run_person(job: PersonJob) -> dict:
    """Run ``job.batch.steps`` for one person, skipping what an earlier run finished. Returns the final
    status (``state`` "done" or "failed"); writes it to ``<OUT>/<name>/status.json`` after every step."""
    job.folder.mkdir(parents=True, exist_ok=True)
    status = TaskStatus(job.folder, job.person.name, job.person.source)
    if all(_step_current(job, status, s) for s in job.batch.steps):
        return status.data
    status.start()
    step = None
    try:
        for step in job.batch.steps:
            if _step_current(job, status, step):
                continue
            status.data["current"] = step  # what the progress display shows while it runs
            status.save()
            t0 = time.perf_counter()
            try:
                facts = STEPS[step](job)
                status.set_step(step, "done", time.perf_counter() - t0, **facts)
            except StepSkipped as why:
                status.set_step(step, "skipped", time.perf_counter() - t0, reason=str(why))
    except Exception as exc:  # recorded, not raised: the batch goes on with the others
        message = " ".join(str(exc).split()) or type(exc).__name__
        status.data["steps"][step] = {"state": "failed"}
        status.finish("failed", f"{step}: {message}", traceback.format_exc())
        return status.data
    status.data["current"] = None
    status.finish("done")
    return status.data


def shared_paths(out: Path, people: list[str]) -> tuple[Path, Path]:
    """(what phase 1 fits into: ``-o`` of its ``gma fit``, its decoders file). With one person that is
    an ordinary avatar, whose decoders ``--decoders`` takes as well."""
    root = Path(out) / SHARED_DIR
    if len(people) == 1:
        return root / f"{people[0]}.gma", root / f"{people[0]}.gma"
    return root / "fit", root / "fit" / "decoders.gma"


def phase1_config(fit: FitConfig, people: int) -> FitConfig:
    """The fit of phase 1: the steps of one fit per person of the subset, since the shared fit's steps take
    the people in turn (so each sees as many steps as its own fit would give it)."""
    return dataclasses.replace(fit, stage1_steps=fit.stage1_steps * people, stage2_steps=fit.stage2_steps * people)


def run_shared_decoders(jobs: list[PersonJob]) -> dict:
    """Phase 1: ``gma fit SEQ1 ... SEQk -o OUT/_shared/fit`` over the people of ``jobs`` (their sequences
    imported already; :func:`phase1_config` steps), resumable like any fit. Returns the status of
    ``OUT/_shared`` with ``avatars``: {person name: avatar file} and ``decoders``: the decoders file."""
    names = [j.person.name for j in jobs]
    target, decoders = shared_paths(jobs[0].out, names)
    status = TaskStatus(jobs[0].out / SHARED_DIR, SHARED_DIR, ",".join(names))
    if status.data["state"] == "done" and decoders.is_file():
        return status.data
    status.start()
    t0 = time.perf_counter()
    try:
        seqs = [job.sequence() for job in jobs]
        fit = phase1_config(jobs[0].fit, len(jobs))
        prepare_fit_outputs(target, seqs, resume=True)
        trainer = Trainer(fit, seqs if len(seqs) > 1 else seqs[0], target, body=worker_body(fit.avatar.body),
                          ctx=worker_context(), progress=False, finish=AfterFit(worker_context()))
        trainer.run(resume=True)
        avatars = {name: str(p) for name, p in zip(names, subject_outputs(target, [s.root for s in seqs]), strict=True)}
        status.data.update(avatars=avatars, decoders=str(decoders))
        status.set_step("fit", "done", time.perf_counter() - t0, people=len(jobs))
    except Exception as exc:
        status.finish("failed", f"shared decoders: {' '.join(str(exc).split())}", traceback.format_exc())
        return status.data
    status.finish("done")
    return status.data
