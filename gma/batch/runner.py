"""The batch on Ray: one Ray task per person, a local runtime on this machine when no cluster address is
given, so the same command runs on a laptop and on a cluster.

Order of work: people whose every requested step is recorded as done are skipped without a task; with
shared decoders, the decoder subset is imported first (one task each), phase 1 fits the decoders (one
task), then every person's task runs the remaining steps, the others fitting only their features. Results
are gathered as they finish (``ray.wait``), so one slow or failed person holds up no other.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from collections.abc import Callable
from pathlib import Path

from tqdm import tqdm

from gma.batch.cluster import import_ray, runtime_env
from gma.batch.config import BatchConfig, Person
from gma.batch.status import TaskStatus
from gma.batch.steps import PersonJob
from gma.batch.summary import summary_rows, write_summary
from gma.batch.task import SHARED_DIR, is_finished, run_person, run_shared_decoders
from gma.core.atomic import atomic_write_json
from gma.core.errors import InputError, OutputError
from gma.train.config import FitConfig

__all__ = ["check_batch_folder", "run_batch"]

BATCH_FILE = "batch.json"


def check_batch_folder(out: Path, batch: BatchConfig, fit: FitConfig, people: list[Person]) -> None:
    """A batch folder is resumed only with the options that made it: another fit config or another decoder
    subset would mix incomparable avatars (and the fits' own checkpoints would refuse to continue).
    Steps, Ray settings and people may change between runs."""
    saved_path = out / BATCH_FILE
    if out.exists() and not out.is_dir():
        raise OutputError(f"{out}: is a file; the batch output is a folder")
    if not saved_path.is_file():
        if out.is_dir() and any(p for p in out.iterdir() if not p.name.startswith(".")):
            raise OutputError(f"{out}: exists and is not a gma batch folder (no {BATCH_FILE}); name a new folder")
        return
    try:
        saved = json.loads(saved_path.read_text())
    except (OSError, ValueError) as exc:
        raise InputError(f"{saved_path}: unreadable ({exc}); remove it only if the folder's fits may start "
                         "over") from None
    if saved.get("fit") != fit.to_dict() or saved.get("batch", {}).get("train_decoders") != batch.train_decoders:
        raise InputError(f"{saved_path}: this batch folder was made with other fit options; re-run with the same "
                         "options (see the file) or give another -o")
    before = {p["name"]: p["source"] for p in saved.get("people", [])}
    for p in people:
        if before.get(p.name, p.source) != p.source:
            raise InputError(f"{p.source}: its name {p.name!r} belongs to {before[p.name]} in this batch folder; "
                             "rename the input or give another -o")


def _record(out: Path, batch: BatchConfig, fit: FitConfig, people: list[Person]) -> None:
    saved = {}
    try:
        saved = json.loads((out / BATCH_FILE).read_text())
    except (OSError, ValueError):
        pass
    known = {p["name"]: p for p in saved.get("people", [])}
    known.update({p.name: p.to_dict() for p in people})
    atomic_write_json(out / BATCH_FILE, {"format": "gma-batch", "version": 1, "batch": batch.to_dict(),
                                         "fit": fit.to_dict(), "people": list(known.values())})


def _crashed(job: PersonJob, exc: BaseException) -> dict:
    """A task that died without a word (worker killed, out of memory, node lost): its status says so."""
    status = TaskStatus(job.folder, job.person.name, job.person.source)
    line = " ".join(str(exc).split())[:300] or type(exc).__name__
    status.finish("failed", f"worker lost ({type(exc).__name__}): {line}")
    return status.data


def _running(pending: dict) -> str:
    """"name:step" of the people still running, from their status files (a cheap read every few seconds)."""
    now = []
    for job in pending.values():
        status = TaskStatus.read(job.folder) or {}
        if status.get("state") == "running" and status.get("current"):
            now.append(f"{job.person.name}:{status['current']}")
    return " ".join(now[:4]) + (" ..." if len(now) > 4 else "")


def _gather(ray, pending: dict, bar, report: Callable[[str], None]) -> dict:
    """Wait for every ref of ``pending`` ({ref: job}); returns {person name: final status}. The bar shows
    finished people, failures, and the step each running person is in (as Ray's own progress bars do)."""
    results, failed = {}, 0
    while pending:
        ready, _ = ray.wait(list(pending), num_returns=1, timeout=2.0)
        if not ready:
            bar.set_postfix(failed=failed, now=_running(pending), refresh=True)
            continue
        job = pending.pop(ready[0])
        try:
            status = ray.get(ready[0])
        except Exception as exc:  # ray.exceptions.RayError and its kin: the worker, not the person
            status = _crashed(job, exc)
        results[job.person.name] = status
        failed += status["state"] != "done"
        bar.update(1)
        bar.set_postfix(failed=failed, now=_running(pending))
        tail = f": {status['error']}" if status.get("error") else ""
        report(f"[batch] {job.person.name} {status['state']} ({status.get('seconds', 0):.0f} s){tail}")
    return results


def run_batch(inputs: list[Person], out: str | Path, batch: BatchConfig, fit: FitConfig,
              progress: bool = True, ray_init: dict | None = None) -> list[dict]:
    """Run the batch; returns the summary rows (also written as ``OUT/summary.csv`` and ``summary.md``).
    ``ray_init`` adds keyword arguments to ``ray.init`` (tests pass ``num_cpus``)."""
    ray = import_ray()
    out = Path(out).resolve()
    if batch.train_decoders and fit.decoders:
        raise InputError("--train-decoders and --decoders contradict each other: train shared decoders here, or "
                         "use given ones")
    if batch.train_decoders > len(inputs):
        raise InputError(f"--train-decoders {batch.train_decoders}: only {len(inputs)} people given")
    check_batch_folder(out, batch, fit, inputs)
    out.mkdir(parents=True, exist_ok=True)
    _record(out, batch, fit, inputs)
    report = (lambda line: tqdm.write(line, file=sys.stderr)) if progress else (lambda line: None)

    subset = inputs[:batch.train_decoders]
    jobs = {p.name: PersonJob(p, out, batch, fit) for p in inputs}
    finished = {name for name, job in jobs.items() if is_finished(job)}
    if len(finished) == len(jobs):  # nothing to do: no runtime to start
        report(f"[batch] all {len(jobs)} people are done already")
        rows = summary_rows(out, list(jobs.values()))
        write_summary(out, rows)
        return rows

    started_here = not ray.is_initialized()
    if started_here:
        kwargs = {"include_dashboard": False, "log_to_driver": False, "runtime_env": runtime_env(),
                  **(ray_init or {})}
        if batch.address:
            kwargs["address"] = batch.address
        ray.init(**kwargs)
    try:
        opts = {"num_cpus": batch.cpus_per_task, "num_gpus": batch.gpus_per_task, "max_retries": 0}
        person_task = ray.remote(run_person).options(**opts)
        bar = tqdm(total=len(inputs), desc="batch", unit="person", disable=not progress, dynamic_ncols=True)
        results: dict = {name: TaskStatus.read(jobs[name].folder) for name in finished}
        if subset:  # quick when phase 1 finished in an earlier run: it only points the jobs at its decoders
            results.update(_phase1(ray, opts, [jobs[p.name] for p in subset], jobs, fit, report))
        bar.update(len(results))
        pending = {person_task.remote(job): job for name, job in jobs.items() if name not in results}
        results.update(_gather(ray, pending, bar, report))
        bar.close()
    finally:
        if started_here:
            ray.shutdown()
    rows = summary_rows(out, [jobs[p.name] for p in inputs])
    write_summary(out, rows, _shared_note(out) if subset else [])
    return rows


def _shared_note(out: Path) -> list[str]:
    """A line on phase 1 for the summary: its time is nobody's row."""
    status = TaskStatus.read(out / SHARED_DIR)
    if status is None:
        return []
    return [f"Shared decoders (phase 1, {status['source']}): {status['state']} in {status.get('seconds', 0):.0f} s"
            + (f"; {status['error']}" if status.get("error") else "") + "."]


def _phase1(ray, opts: dict, subset: list[PersonJob], jobs: dict, fit: FitConfig, report) -> dict:
    """Import the decoder subset, train the shared decoders over it, and point every job at them. Returns
    the statuses of people who cannot go on (their import failed, or phase 1 did)."""
    if "import" in subset[0].batch.steps:
        only_import = dataclasses.replace(subset[0].batch, steps=("import",))
        refs = [ray.remote(run_person).options(**opts).remote(dataclasses.replace(j, batch=only_import))
                for j in subset]
        try:
            statuses = ray.get(refs)
        except Exception as exc:  # a worker lost during the import
            return _fail_all(jobs, f"shared decoders: worker lost during the import ({type(exc).__name__})", report)
        for job, status in zip(subset, statuses, strict=True):
            if status["state"] != "done":
                return _fail_all(jobs, f"shared decoders: {job.person.name} could not be imported "
                                       f"({status['error']})", report)
    report(f"[batch] phase 1: shared decoders over {', '.join(j.person.name for j in subset)}")
    try:
        shared = ray.get(ray.remote(run_shared_decoders).options(**opts).remote(subset))
    except Exception as exc:  # the worker of phase 1 died; its fit resumes from its checkpoint next time
        return _fail_all(jobs, f"shared decoders: worker lost ({type(exc).__name__})", report)
    if shared["state"] != "done":
        return _fail_all(jobs, shared["error"], report)
    for job in jobs.values():
        if job.person.name in shared["avatars"]:
            job.shared_avatar = shared["avatars"][job.person.name]
        else:
            job.fit = dataclasses.replace(fit, decoders=shared["decoders"])
    return {}


def _fail_all(jobs: dict, error: str, report) -> dict:
    """Phase 1 failed: nobody can be fitted against decoders that do not exist; each status says why."""
    report(f"[batch] {error}; no one is fitted")
    results = {}
    for name, job in jobs.items():
        if is_finished(job):  # done in an earlier run: its avatar stands
            results[name] = TaskStatus.read(job.folder)
            continue
        job.folder.mkdir(parents=True, exist_ok=True)
        status = TaskStatus(job.folder, name, job.person.source)
        status.finish("failed", error)
        results[name] = status.data
    return results
