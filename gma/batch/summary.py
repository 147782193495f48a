"""The batch's summary table, one row per person (status, time, novel-view PSNR where the sequence has
that split, avatar file size, the share of the body surface no frame showed well and the fit guessed),
as ``OUT/summary.csv`` and ``OUT/summary.md``, both written atomically."""

from __future__ import annotations

import csv
import io
from pathlib import Path

from gma.batch.status import TaskStatus
from gma.core.atomic import atomic_write_bytes

__all__ = ["COLUMNS", "format_markdown", "summary_rows", "write_summary"]

COLUMNS = ("person", "status", "seconds", "novel_view_psnr", "novel_pose_psnr", "avatar_mb", "guessed_pct",
           "resumed_from", "error")


def summary_rows(out: Path, jobs: list) -> list[dict]:
    """The rows of the people of ``jobs`` (:class:`gma.batch.steps.PersonJob`), read from their status files."""
    rows = []
    for job in jobs:
        st = TaskStatus.read(job.folder) or {"state": "pending", "steps": {}}
        ev, fit = st["steps"].get("eval", {}), st["steps"].get("fit", {})
        avatar = job.avatar_path
        rows.append({"person": job.person.name, "status": st["state"], "seconds": round(st.get("seconds", 0.0), 1),
                     "novel_view_psnr": ev.get("test_view_psnr"), "novel_pose_psnr": ev.get("test_pose_psnr"),
                     "avatar_mb": round(avatar.stat().st_size / 2**20, 3) if avatar.is_file() else None,
                     "guessed_pct": _percent(fit.get("guessed_area")), "resumed_from": fit.get("resumed_from"),
                     "error": st.get("error")})
    return rows


def _percent(share: float | None) -> float | None:
    return None if share is None else round(100 * share, 1)


def _cell(value) -> str:
    if value is None:
        return ""
    if isinstance(value, float):
        return f"{value:.2f}"
    return str(value)


def format_markdown(rows: list[dict], notes: list[str] = ()) -> str:
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for r in rows:
        lines.append("| " + " | ".join(_cell(r[c]).replace("|", "\\|") for c in COLUMNS) + " |")
    done = sum(r["status"] == "done" for r in rows)
    lines.append("")
    lines.append(f"{done} of {len(rows)} people done; {len(rows) - done} failed or pending.")
    lines.extend(notes)
    return "\n".join(lines) + "\n"


def write_summary(out: str | Path, rows: list[dict], notes: list[str] = ()) -> None:
    """``OUT/summary.csv`` (one row per person) and ``OUT/summary.md`` (the table, then ``notes``)."""
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS, lineterminator="\n")
    writer.writeheader()
    writer.writerows({c: _cell(r[c]) for c in COLUMNS} for r in rows)
    atomic_write_bytes(Path(out) / "summary.csv", buf.getvalue().encode())
    atomic_write_bytes(Path(out) / "summary.md", format_markdown(rows, notes).encode())
