#!/usr/bin/env python3
"""Where a render's CPU time goes on lavapipe, pass by pass. Renders the standard scene forward and
backward (as shader_ab.py does) for a while under `perf record`, places every sample in the GPU pass
that ran at that instant (lavapipe's timestamps are the CPU's monotonic clock, which perf is told to
use), and splits each pass's samples by what ran: the pass's own shader code, JIT code that several
passes share (llvmpipe compiles texel fetches and stores into functions of their own that every
shader calls), libc (memcpy), the driver, the kernel, the rest. Samples outside the timed passes are
the host's work and the untimed copies.

    python benchmarks/lavapipe_profile.py [--seconds 20] [--count 100000] [--scene avatar --size 512]

Needs `perf` (Debian: linux-perf) and leave to sample this process (kernel.perf_event_paranoid <= 2);
without them, or on a GPU, it says so and exits 0. Its CPU milliseconds per step are over all threads
(lavapipe runs a pass on one thread per core), so a pass's CPU ms is about cores x its wall ms.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import PASSES, machine, pass_inputs, scene_and_camera  # noqa: E402

from gma.gpu import PassTimer, get_context  # noqa: E402
from gma.render import SurfelRasterizer, read_outputs  # noqa: E402
from gma.render.rasterizer import MAX_SURFELS  # noqa: E402

KINDS = ("shader", "shared JIT", "libc", "driver", "kernel", "other")
OUTSIDE = "(outside passes)"
WINDOW_BITS = 8   # JIT code is grouped in 256-byte windows to tell a pass's own code from shared code


def parse_samples(text: str) -> list[tuple[int, int, str]]:
    """(time ns, instruction address, object) per line of ``perf script -F time,ip,dso --ns``."""
    out = []
    for line in text.splitlines():
        parts = line.split(None, 2)
        if len(parts) < 2 or not parts[0].endswith(":"):
            continue
        try:
            sec, frac = parts[0][:-1].split(".")
            t = int(sec) * 1_000_000_000 + int(frac.ljust(9, "0")[:9])
            ip = int(parts[1], 16)
        except ValueError:
            continue
        out.append((t, ip, parts[2].strip("() ") if len(parts) > 2 else ""))
    return out


def kind_of(dso: str) -> str:
    """What ran, from perf's object name (JIT code has none, or a perf-PID.map that nobody wrote)."""
    if not dso or dso == "[unknown]" or "perf-" in dso or "anon" in dso:
        return "jit"
    if "libc.so" in dso:
        return "libc"
    if "lvp" in dso or "vulkan" in dso or "LLVM" in dso:
        return "driver"
    if "kernel" in dso:
        return "kernel"
    return "other"


def attribute(samples: list[tuple[int, int, str]], intervals: list[tuple[str, int, int]]
              ) -> tuple[dict[str, collections.Counter], dict[int, collections.Counter]]:
    """Per pass name (and OUTSIDE), sample counts by kind (KINDS); and per 256-byte JIT window, its samples
    by pass. JIT code sampled in two or more passes counts as shared, the rest as the pass's shader."""
    intervals = sorted(intervals, key=lambda iv: iv[1])
    starts = [iv[1] for iv in intervals]
    placed = []
    windows: dict[int, collections.Counter] = collections.defaultdict(collections.Counter)
    for t, ip, dso in samples:
        i = bisect.bisect_right(starts, t) - 1
        name = intervals[i][0] if i >= 0 and t <= intervals[i][2] else OUTSIDE
        kind = kind_of(dso)
        placed.append((name, kind, ip))
        if kind == "jit" and name != OUTSIDE:
            windows[ip >> WINDOW_BITS][name] += 1
    table: dict[str, collections.Counter] = collections.defaultdict(collections.Counter)
    for name, kind, ip in placed:
        if kind == "jit":
            kind = "shared JIT" if len(windows.get(ip >> WINDOW_BITS, ())) >= 2 else "shader"
        table[name][kind] += 1
    return table, windows


def perf_usable() -> str | None:
    """Why perf cannot sample this process, or None."""
    if shutil.which("perf") is None:
        return "perf not found (Debian: apt-get install linux-perf)"
    try:
        level = int(Path("/proc/sys/kernel/perf_event_paranoid").read_text())
    except (OSError, ValueError):
        return None
    if level > 2 and os.geteuid() != 0:
        return f"kernel.perf_event_paranoid is {level}: sampling this process needs <= 2 (or root)"
    return None


def _check_args(args) -> str | None:
    """Why the arguments cannot be used, or None."""
    if not 0 < args.seconds <= 600:
        return f"--seconds {args.seconds}: must lie in (0, 600]"
    if not 1 <= args.count <= MAX_SURFELS:
        return f"--count {args.count}: must lie in 1..{MAX_SURFELS}"
    if not 16 <= args.size <= 4096 or not 10 <= args.frequency <= 20000:
        return "--size must lie in 16..4096 and --frequency in 10..20000"
    return None


def _cannot_profile(ctx) -> str | None:
    """Why this adapter and machine cannot be profiled, or None."""
    if not ctx.is_lavapipe:   # its timestamps are the CPU's clock, and its passes run as CPU code
        return "not lavapipe: nothing to profile"
    if not ctx.has_timestamps:
        return "the adapter has no timestamp queries: passes cannot be placed in time"
    return perf_usable()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="how long to sample")
    ap.add_argument("--count", type=int, default=100000, help="surfels of the scene")
    ap.add_argument("--scene", choices=("standard", "avatar"), default="standard")
    ap.add_argument("--size", type=int, default=512, help="image side of the avatar scene")
    ap.add_argument("--frequency", type=int, default=1999, help="samples per second and core")
    args = ap.parse_args()
    bad = _check_args(args)
    if bad:
        print(bad, file=sys.stderr)
        return 2
    ctx = get_context()
    print(f"adapter: {ctx.name}; {machine()}")
    why = _cannot_profile(ctx)
    if why:
        print(why)
        return 0
    scene, cam = scene_and_camera(args.count, args.scene, args.size)
    surfels, upstream = pass_inputs(ctx, scene, cam)
    rast, timer = SurfelRasterizer(ctx), PassTimer(ctx)

    def step() -> list[tuple[str, int, int]]:
        state = rast.forward(surfels, cam, timer=timer)
        read_outputs(ctx, state)
        passes = timer.intervals()
        rast.backward(state, surfels, upstream, None, None, None, timer=timer)
        return passes + timer.intervals()

    for _ in range(2):   # pipelines and capacities
        step()
    recorded = _record(step, args)
    if isinstance(recorded, str):
        print(recorded)
        return 0
    _print_table(*recorded, args)
    return 0


def _record(step, args):
    """Run ``step`` for ``args.seconds`` under ``perf record``: (samples, pass intervals, steps), or why
    nothing was recorded."""
    with tempfile.TemporaryDirectory(prefix="gma-perf-") as tmp:
        data = Path(tmp) / "perf.data"
        rec = subprocess.Popen(["perf", "record", "-q", "-k", "CLOCK_MONOTONIC", "-F", str(args.frequency),
                                "-p", str(os.getpid()), "-o", str(data)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        time.sleep(1.0)   # perf attaches to every thread
        if rec.poll() is not None:
            return f"perf record did not start: {rec.stderr.read().decode(errors='replace').strip()[:300]}"
        intervals, steps, t_end = [], 0, time.monotonic() + args.seconds
        while time.monotonic() < t_end:
            intervals += step()
            steps += 1
        rec.send_signal(signal.SIGINT)
        try:
            rec.wait(timeout=60)
        except subprocess.TimeoutExpired:
            rec.kill()
            return "perf record did not stop within 60 s after SIGINT: nothing to report"
        script = subprocess.run(["perf", "script", "-i", str(data), "-F", "time,ip,dso", "--ns"],
                                capture_output=True, text=True, timeout=300)
    samples = parse_samples(script.stdout)
    if not samples:
        return f"perf recorded no samples: {script.stderr.strip()[:300]}"
    return samples, intervals, steps


def _print_table(samples, intervals, steps: int, args) -> None:
    """CPU time per pass and step by what ran (from the samples), wall time per pass, and the JIT code
    windows that several passes share."""
    table, windows = attribute(samples, intervals)
    per_step = 1e3 / args.frequency / steps   # CPU ms per step of one sample
    wall = collections.defaultdict(float)
    for name, t0, t1 in intervals:
        wall[name] += (t1 - t0) * 1e-6 / steps
    print(f"{steps} steps (forward, images read, backward) of {args.count} surfels, {len(samples)} samples")
    kinds = " ".join(f"{k:>10s}" for k in KINDS)
    print(f"{'pass':16s} {'wall ms':>8s} {'CPU ms':>8s} {kinds}   (CPU ms per step by what ran)")
    names = [n for n in PASSES if n in table] + sorted(set(table) - set(PASSES) - {OUTSIDE}) + [OUTSIDE]
    for name in names:
        counts = table.get(name, collections.Counter())
        cells = " ".join(f"{counts[k] * per_step:10.2f}" for k in KINDS)
        print(f"{name:16s} {wall.get(name, float('nan')):8.2f} {sum(counts.values()) * per_step:8.2f} {cells}")
    shared = sorted(((sum(c.values()), w, c) for w, c in windows.items() if len(c) >= 2), reverse=True)[:8]
    if shared:
        print("busiest shared JIT code (256-byte windows: CPU ms per step, by pass)")
        for total, w, c in shared:
            by = ", ".join(f"{n} {v * per_step:.2f}" for n, v in c.most_common())
            print(f"  {w << WINDOW_BITS:#x}  {total * per_step:6.2f}  {by}")


if __name__ == "__main__":
    sys.exit(main())
