#!/usr/bin/env python3
"""The user-facing figures in one generated file: runs the benchmark scripts beside this one, each in its
own process with the arguments below, and writes ``benchmarks/RESULTS.md``: the machine (processor,
cores), the adapter and its driver, the commit, the date and this command, a table of headline figures,
and each script's own output.

    python benchmarks/report.py                 # the default set on this machine's adapter
    python benchmarks/report.py --gpu           # the same set on a hardware GPU (GMA_ADAPTER=gpu)
    python benchmarks/report.py --quick         # tiny sizes: checks that the report is made, figures mean nothing
    python benchmarks/report.py --only render peer --out /tmp/results.md
    python benchmarks/report.py --only web --update   # rerun one row, keep the others of the last report

A row whose prerequisite is missing (gsplat for the peer ratio, MediaPipe for the video) says so instead
of a figure; a script that fails leaves its exit status and last lines in the report, and the others run.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import re
import shlex
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

BENCH = Path(__file__).resolve().parent
REPO = BENCH.parent
sys.path.insert(0, str(BENCH))
from common import cpu_name  # noqa: E402

DEFAULT_OUT = BENCH / "RESULTS.md"
OUTPUT_LINES = 40  # of a script's output kept in the report


@dataclasses.dataclass(frozen=True)
class Bench:
    """One benchmark of the report: the script, its arguments (``{tmp}``: a fresh folder, ``{json}``: a file
    the script writes its numbers to), what it needs, and how its headline figures are read."""

    name: str
    title: str
    script: str
    args: list[str]
    quick_args: list[str]
    figures: Callable[[str, dict], list[tuple[str, str]]]
    missing: Callable[[], str | None] = lambda: None
    timeout_s: int = 1800


# -- headline figures from each script's output ------------------------------------------------------------
def _render_figures(_out: str, data: dict) -> list[tuple[str, str]]:
    rows = []
    for r in data.get("rows", []):
        if "frame_ms" in r:
            name = f"forward frame, {r['scene']} surfels at {r['width']}x{r['height']}"
            rows.append((name, f"{r['frame_ms']:.1f} ms"))
    return rows


def _peer_figures(_out: str, data: dict) -> list[tuple[str, str]]:
    return [(f"{r['pass']}, standard scene {r['n']:,} surfels: GMA / gsplat torch 2DGS",
             f"{r['gma_ms']:.1f} / {r['peer_ms']:.1f} ms = **{r['ratio']:.1f}x**") for r in data.get("rows", [])]


def _matches(pattern: str, out: str, label: Callable[[re.Match], tuple[str, str]]) -> list[tuple[str, str]]:
    return [label(m) for m in re.finditer(pattern, out, re.MULTILINE)]


def _fit_step_figures(out: str, _data: dict) -> list[tuple[str, str]]:
    return _matches(r"this checkout\s+(pose-fitting step|training step)\s+median\s+([\d.]+) ms", out,
                    lambda m: (f"{m[1]} (quick preset, synthetic sequence)", f"{m[2]} ms"))


def _viewer_fps_figures(out: str, _data: dict) -> list[tuple[str, str]]:
    size = re.search(r"; (\d+x\d+), \d+ frames per run", out)
    where = f" at {size[1]}" if size else ""
    return _matches(r"^(avatar|body)\s+(\d+)\s+([\d.]+)\s+([\d.]+)\s+([\d.]+)\s+\d+\s+[\d.]+\s+(True|False)", out,
                    lambda m: (f"viewer, {m[1]} of {int(m[2]):,} surfels{where}: every frame full / orbit / playing",
                               f"{m[3]} / {m[4]} / {m[5]} FPS"))


def _viewer_edit_figures(out: str, _data: dict) -> list[tuple[str, str]]:
    rows = _matches(r"painted colour on screen (\d+) ms; solved features on screen (\d+) ms", out,
                    lambda m: ("edit: paint release -> painted colour / solved features on screen",
                               f"{m[1]} / {m[2]} ms"))
    rows += _matches(r"while dragging: median ([\d.]+) frames/s", out,
                     lambda m: ("edit: brush stroke while dragging", f"{m[1]} frames/s"))
    return rows


def _video_figures(out: str, _data: dict) -> list[tuple[str, str]]:
    return _matches(r"^synthetic turn, (\d+) frames at (\d+) px, quick preset: import (\d+) s, fit (\d+) s, "
                    r"video -> avatar (\d+) s; held-out bbox PSNR ([\d.]+) dB", out,
                    lambda m: (f"video -> avatar, {m[1]}-frame synthetic mp4 at {m[2]} px: import / fit / total "
                               "(held-out bbox PSNR)", f"{m[3]} / {m[4]} / {m[5]} s ({m[6]} dB)"))


def _web_figures(out: str, _data: dict) -> list[tuple[str, str]]:
    rows = _matches(r"^page: ([\d.]+) MB", out,
                    lambda m: ("web page (gma export .html), quick-preset-sized avatar, 4 s walk: size", f"{m[1]} MB"))
    psnr = re.findall(r"PSNR in the person's box ([\d.]+) dB", out)
    if psnr:
        rows.append(("web page against gma render, PSNR in the person's box at 512x512 (frames)",
                     " / ".join(psnr) + " dB"))
    fps = re.findall(r"^(playing|paused) at 640²: ([\d.]+) FPS", out, re.MULTILINE)
    if fps:
        rows.append(("web page at 640x640, headless Chromium, software WebGL: " + " / ".join(k for k, _ in fps),
                     " / ".join(v for _, v in fps) + " FPS"))
    return rows


# -- prerequisites ------------------------------------------------------------------------------------------
def _gsplat_missing() -> str | None:
    import peer_gsplat

    return "gsplat not installed" if peer_gsplat.missing_reason() else None


def _web_page_missing() -> str | None:
    import web_browser

    from gma.export.web import BUNDLE

    if not BUNDLE.is_file():
        return "the web page's JavaScript is not built (cd web && npm ci && npm run build)"
    return web_browser.missing_browser()


def _mediapipe_missing() -> str | None:
    import importlib.util

    return None if importlib.util.find_spec("mediapipe") else "MediaPipe not installed (pip install 'gma[video]')"


BENCHES = [
    Bench("render", "Renderer forward", "render.py",
          ["--repeats", "3", "--sizes", "512", "--counts", "200000", "--standard-counts", "100000",
           "--reference-count", "3000", "--reference-size", "96", "--json", "{json}"],
          ["--repeats", "1", "--sizes", "64", "--counts", "500", "--standard-counts", "500",
           "--reference-count", "300", "--reference-size", "32", "--json", "{json}"],
          _render_figures),
    Bench("fit", "Fit steps", "fit_step.py", ["--repeats", "3", "--steps", "4", "--work", "{tmp}"],
          ["--repeats", "1", "--steps", "1", "--work", "{tmp}"], _fit_step_figures),
    Bench("video", "Video to avatar (quick preset)", "video_to_avatar.py",
          ["--work", "{tmp}", "--time-only", "--frames", "16", "--size", "128"],
          ["--work", "{tmp}", "--time-only", "--frames", "4", "--size", "64"],
          _video_figures, _mediapipe_missing),
    Bench("viewer", "Viewer frame rates", "viewer_fps.py", ["--size", "800x600", "--frames", "30"],
          ["--size", "96x64", "--surfels", "2000", "--frames", "3", "--fine-per-face", "1"], _viewer_fps_figures),
    Bench("edit", "Editing in the viewer", "viewer_edit.py", ["--size", "640x480", "--repeats", "3"],
          ["--size", "96x64", "--fine-per-face", "1", "--feature-dim", "8", "--faces", "100", "--repeats", "1",
           "--stroke-frames", "3"], _viewer_edit_figures),
    Bench("web", "The avatar as a web page", "web_export.py", [], [], _web_figures, _web_page_missing),
    Bench("peer", "Against gsplat's PyTorch 2DGS path (peer ratio)", "peer_compare.py",
          ["--counts", "100000", "--repeats", "3", "--json", "{json}"],
          ["--counts", "500", "--repeats", "1", "--json", "{json}"], _peer_figures, _gsplat_missing),
]
NAMES = [b.name for b in BENCHES]


@dataclasses.dataclass
class Outcome:
    bench: Bench
    command: str
    status: str                      # "ok", "not measured: ...", "not run: ...", "failed: ..."
    output: str = ""
    figures: list[tuple[str, str]] = dataclasses.field(default_factory=list)
    seconds: float = 0.0
    ran: str = ""                    # when, at which commit and load (set by main)

    def to_json(self) -> dict:
        return {"name": self.bench.name, "command": self.command, "status": self.status, "output": self.output,
                "figures": [list(f) for f in self.figures], "seconds": self.seconds, "ran": self.ran}

    @staticmethod
    def from_json(d: dict) -> Outcome:
        bench = next(b for b in BENCHES if b.name == d["name"])
        return Outcome(bench, d["command"], d["status"], d["output"], [tuple(f) for f in d["figures"]],
                       d["seconds"], d["ran"])


def run_bench(bench: Bench, quick: bool, env: dict[str, str]) -> Outcome:
    """Run one script in its own process and read its figures; never raises for the script's failure."""
    args = bench.quick_args if quick else bench.args
    readable = [a.format(tmp="WORK", json="FIGURES.json") for a in args]  # the temporary paths, by role
    shown = " ".join(["python", f"benchmarks/{bench.script}", *readable])
    reason = bench.missing()
    if reason:
        return Outcome(bench, shown, f"not measured: {reason}")
    with tempfile.TemporaryDirectory(prefix=f"gma-report-{bench.name}-") as tmp:
        json_path = Path(tmp) / "figures.json"
        argv = [a.format(tmp=tmp, json=json_path) for a in args]
        t0 = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, str(BENCH / bench.script), *argv], cwd=REPO, env=env,
                                  capture_output=True, text=True, timeout=bench.timeout_s)
        except subprocess.TimeoutExpired:
            return Outcome(bench, shown, f"failed: still running after {bench.timeout_s} s")
        seconds = time.perf_counter() - t0
        output = (proc.stdout + ("\n" + proc.stderr if proc.returncode else "")).strip()
        if proc.returncode:
            last = proc.stderr.strip().splitlines()[-1:] or ["(no message)"]
            return Outcome(bench, shown, f"failed (exit {proc.returncode}): {last[0]}", output, seconds=seconds)
        data = json.loads(json_path.read_text()) if json_path.is_file() else {}
    return Outcome(bench, shown, "ok", proc.stdout.strip(), bench.figures(proc.stdout, data), seconds)


# -- what the report says about where it ran ----------------------------------------------------------------
def commit() -> str:
    """The checkout's commit, marked when the working tree differs from it."""
    def git(*args):
        return subprocess.run(["git", "-C", str(REPO), *args], capture_output=True, text=True, timeout=30)

    head = git("rev-parse", "--short=12", "HEAD")
    if head.returncode:
        return "unknown (not a git checkout)"
    dirty = git("status", "--porcelain", "--untracked-files=no").stdout.strip()
    return head.stdout.strip() + (" with uncommitted changes" if dirty else "")


def machine_lines(adapter) -> list[str]:
    import torch

    from gma.gpu.adapter import describe

    info = adapter.info
    return [f"- machine: {cpu_name()}, {os.cpu_count()} cores, {platform.system()} {platform.release()}; "
            f"torch {torch.__version__} ({torch.backends.cpu.get_cpu_capability()}, "
            f"{torch.get_num_threads()} threads)",
            f"- adapter: {describe(adapter)}; driver: {info.get('description') or 'not reported'}",
            f"- load average before the run: {os.getloadavg()[0]:.2f}" if hasattr(os, "getloadavg") else ""]


def render_markdown(header: list[str], outcomes: list[Outcome], quick: bool) -> str:
    lines = ["# Benchmark results", "",
             "Generated by `benchmarks/report.py`; do not edit by hand. Figures are medians of the runs each "
             "script makes; they depend on the machine and its load, so compare figures only within one file.",
             "", *[h for h in header if h], ""]
    if quick:
        lines += ["**Quick mode: tiny sizes, the figures mean nothing.**", ""]
    lines += ["| figure | value |", "|---|---|"]
    for o in outcomes:
        if o.status != "ok":
            lines.append(f"| {o.bench.title} | {o.status} |")
        for name, value in o.figures:
            lines.append(f"| {name} | {value} |")
        if o.status == "ok" and not o.figures:
            lines.append(f"| {o.bench.title} | see below |")
    for o in outcomes:
        took = f"{o.seconds:.0f} s" if o.seconds else ""
        when = ", ".join(x for x in (took, o.ran and f"run {o.ran}") if x)
        lines += ["", f"## {o.bench.title}", "", f"`{o.command}`" + (f" ({when})" if when else ""), ""]
        if o.status != "ok":
            lines += [o.status, ""]
        if o.output:
            kept = o.output.splitlines()[-OUTPUT_LINES:]
            lines += ["```", *kept, "```"]
    return "\n".join(lines) + "\n"


def parse_args(argv):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="tiny sizes: a smoke test of the report itself")
    ap.add_argument("--gpu", action="store_true", help="run on a hardware GPU (refused when there is none)")
    ap.add_argument("--only", nargs="+", metavar="NAME", help=f"run only these of {', '.join(NAMES)}")
    ap.add_argument("--out", type=Path, default=DEFAULT_OUT, help="the report (default benchmarks/RESULTS.md)")
    ap.add_argument("--update", action="store_true",
                    help="with --only: keep the other rows of the report already in --out (from its .json beside "
                         "it, made on this machine); each section says when it ran")
    args = ap.parse_args(argv)
    unknown = sorted(set(args.only or []) - set(NAMES))
    if unknown:
        ap.exit(2, f"--only {' '.join(unknown)}: no such benchmark (choose from {', '.join(NAMES)})\n")
    if args.out.exists() and not args.out.is_file():
        ap.exit(2, f"{args.out}: not a file\n")
    if not args.out.parent.is_dir():
        ap.exit(2, f"{args.out}: its folder does not exist\n")
    if args.update and not args.only:
        ap.exit(2, "--update: name the rows to run again with --only\n")
    if args.update and not args.out.with_suffix(".json").is_file():
        ap.exit(2, f"{args.out.with_suffix('.json')}: no earlier report to update (run without --update first)\n")
    return args


def earlier_outcomes(path: Path, header: list[str]) -> list[Outcome]:
    """The outcomes of the report whose record is ``path``; refused when it ran on another machine or
    adapter than ``header`` names (figures of two machines do not belong in one file)."""
    try:
        record = json.loads(path.read_text())
        machine = [h for h in record["header"] if h.startswith(("- machine:", "- adapter:"))]
        outcomes = [Outcome.from_json(d) for d in record["outcomes"]]
    except (OSError, ValueError, KeyError, TypeError, StopIteration) as e:
        raise SystemExit(f"{path}: not a report record ({e})") from None
    here = [h for h in header if h.startswith(("- machine:", "- adapter:"))]
    if [h.split(";")[0] for h in machine] != [h.split(";")[0] for h in here]:
        raise SystemExit(f"{path}: made on another machine or adapter; run the whole report here instead")
    return outcomes


def main(argv=None) -> int:
    args = parse_args(argv)
    from gma.core.atomic import atomic_write_bytes
    from gma.gpu.adapter import NoAdapterError, select_adapter

    env = dict(os.environ, PYTHONPATH=str(REPO))
    if args.gpu:
        env["GMA_ADAPTER"] = "gpu"
    try:
        adapter = select_adapter("gpu" if args.gpu else None)
    except NoAdapterError as e:
        print(f"report.py: no adapter for this run: {str(e).splitlines()[-1]}", file=sys.stderr)
        return 2
    command = " ".join(["python", "benchmarks/report.py", *map(shlex.quote, argv if argv is not None
                                                                         else sys.argv[1:])])
    started = datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    header = [f"- command: `{command}`", f"- commit: {commit()}", f"- date: {started}", *machine_lines(adapter)]
    outcomes = []
    ran = f"{started}, commit {header[1].removeprefix('- commit: ')}, load {os.getloadavg()[0]:.2f}"
    for bench in BENCHES:
        if args.only and bench.name not in args.only:
            continue
        print(f"{bench.name}: {bench.script} ...", flush=True)
        outcome = run_bench(bench, args.quick, env)
        outcome.ran = ran
        print(f"{bench.name}: {outcome.status}" + (f" ({outcome.seconds:.0f} s)" if outcome.seconds else ""),
              flush=True)
        outcomes.append(outcome)
    record = args.out.with_suffix(".json")
    if args.update:
        fresh = {o.bench.name: o for o in outcomes}
        kept = {o.bench.name: o for o in earlier_outcomes(record, header)}
        outcomes = [fresh.get(b.name) or kept[b.name] for b in BENCHES if b.name in fresh or b.name in kept]
    atomic_write_bytes(args.out, render_markdown(header, outcomes, args.quick).encode())
    atomic_write_bytes(record, json.dumps({"header": header, "outcomes": [o.to_json() for o in outcomes]},
                                          indent=1).encode())
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
