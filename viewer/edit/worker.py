"""One edit at a time on a background thread, so that a feature solve (longer than a frame) runs beside
the frame loop. The thread is created when the edit is submitted but started only by :meth:`start`: the
window starts it after presenting the frame that shows the edit's preview, so the two do not compete for
the CPU while that frame is drawn."""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field

__all__ = ["EditJob", "EditWorker"]


@dataclass
class EditJob:
    """One edit: ``fn`` returns a :class:`gma.edit.Change` (or a list); ``after`` runs on the caller's thread
    once the change is applied. ``change`` or ``error`` hold the outcome."""

    what: str
    fn: Callable
    after: Callable | None = None
    t0: float = field(default_factory=time.perf_counter)
    change: object = None
    error: BaseException | None = None
    thread: threading.Thread | None = None
    started: bool = False

    def run(self) -> None:
        """Run ``fn`` here; an error is kept for the caller that polls the job (it reports it)."""
        try:
            self.change = self.fn()
        except Exception as exc:
            self.error = exc


class EditWorker:
    """Holds at most one :class:`EditJob` running (or queued to run) on its own thread."""

    def __init__(self):
        self._job: EditJob | None = None

    @property
    def busy(self) -> bool:
        """A job is queued or running."""
        return self._job is not None

    def submit(self, job: EditJob) -> None:
        """Queue ``job`` on a new thread, not started yet (see :meth:`start`). The caller makes sure no
        other job is held (it joins the previous one first)."""
        if self._job is not None:
            raise RuntimeError("an edit is already running")
        job.thread = threading.Thread(target=job.run, name=f"gma-edit-{job.what}", daemon=True)
        self._job = job

    def start(self) -> None:
        """Start the queued job's thread (nothing when it runs already, or when none is held)."""
        job = self._job
        if job is not None and not job.started:
            job.started = True
            job.thread.start()

    def take_finished(self, start: bool = True) -> EditJob | None:
        """The job once its thread has ended (and the worker is free again), or None while it is queued or
        running; ``start`` starts a queued one first."""
        job = self._job
        if job is not None and start:
            self.start()
        if job is None or not job.started or job.thread.is_alive():
            return None
        self._job = None
        return job

    def join(self) -> EditJob | None:
        """Start the held job if needed, wait for it and return it (None when no job is held)."""
        if self._job is None:
            return None
        self.start()
        self._job.thread.join()
        return self.take_finished()
