"""The status file of one task (``OUT/<name>/status.json``, written atomically after every change), which
is what makes a batch resumable: a re-run skips the steps recorded as done and redoes the others (the fit
continues from its own checkpoint).

    {"name", "source", "state": "running" | "done" | "failed", "pid", "host", "updated",
     "seconds": total over runs, "runs": how many times a task started,
     "steps": {step: {"state": "done" | "skipped" | "failed", "seconds", ...step's own facts}},
     "error": one line or null, "traceback": text or null}
"""

from __future__ import annotations

import json
import os
import socket
import time
from pathlib import Path

from gma.core.atomic import atomic_write_json

__all__ = ["STATUS_NAME", "TaskStatus"]

STATUS_NAME = "status.json"


class TaskStatus:
    """Read-modify-write of one status file. Every setter writes it, so a killed task leaves the last
    completed step on disk."""

    def __init__(self, folder: str | os.PathLike, name: str = "", source: str = ""):
        self.path = Path(folder) / STATUS_NAME
        self.data = self.read(self.path) or {"name": name, "source": source, "state": "pending", "seconds": 0.0,
                                             "runs": 0, "steps": {}, "error": None, "traceback": None}

    @staticmethod
    def read(path: str | os.PathLike) -> dict | None:
        """The status at ``path`` (a status file or its folder), or None when there is none or it is damaged
        (a damaged one is as good as none: the task runs again and the fit resumes from its checkpoint)."""
        path = Path(path)
        if path.is_dir():
            path = path / STATUS_NAME
        try:
            data = json.loads(path.read_text())
        except (OSError, ValueError):
            return None
        return data if isinstance(data, dict) and isinstance(data.get("steps"), dict) else None

    def save(self) -> None:
        self.data["updated"] = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        atomic_write_json(self.path, self.data)

    def start(self) -> None:
        self.data.update(state="running", pid=os.getpid(), host=socket.gethostname(), error=None, traceback=None)
        self.data["runs"] = self.data.get("runs", 0) + 1
        self.save()

    def step_done(self, step: str) -> bool:
        return self.data["steps"].get(step, {}).get("state") in ("done", "skipped")

    def set_step(self, step: str, state: str, seconds: float, **facts) -> None:
        self.data["steps"][step] = {"state": state, "seconds": round(seconds, 2), **facts}
        self.data["seconds"] = round(self.data.get("seconds", 0.0) + seconds, 2)
        self.save()

    def finish(self, state: str, error: str | None = None, traceback: str | None = None) -> None:
        self.data.update(state=state, error=error, traceback=traceback)
        self.save()
