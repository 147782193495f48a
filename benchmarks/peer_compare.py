#!/usr/bin/env python3
"""GMA against the comparison peer in one run: the standard scene (``splat_scene.py``), rendered through
the public ``gma.render.rasterize`` call as a user would (upload, render, read back, torch tensors), and
through gsplat 1.5.3's pure-PyTorch 2DGS path (``peer_gsplat.py``), both at torch's default thread count.
Each side runs in its own process, as a user would run it: in one process, the peer's busy OpenMP workers
would take the cores GMA's driver renders with. Turns alternate (GMA, peer, GMA, peer, ...) so that a
machine whose speed drifts affects both sides alike. Each turn waits for the other side's threads to
settle, then renders ``--burst`` times back to back, as a loop of frames or training steps would; the
figures are the medians of the steps after a turn's first ("steady") and of the first steps alone
("after idle": a step after idle cores also pays for waking threads). Prints medians and the ratios.

``--baseline DIR`` also times another GMA checkout (e.g. ``git worktree add /tmp/base <commit>``) in a
worker process, interleaved the same way, so that a speed-up over earlier code is a ratio from one run;
``--baseline . --baseline-env VK_DRIVER_FILES=/usr/share/vulkan/icd.d/lvp_icd.x86_64.json`` times this
same code on the system's lavapipe alone instead of the newer one that ``scripts/lavapipe_backport.py``
installs beside it (the worker's adapter is printed). The baseline's ratio to the peer is printed too.

    BUILD_NO_CUDA=1 pip install gsplat==1.5.3     # once: the peer
    python benchmarks/peer_compare.py [--counts 20000 100000] [--repeats 5] [--burst 3] [--baseline DIR]
                                      [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (  # noqa: E402
    CheckoutWorker,
    load_standard_workload,
    machine,
    parse_env,
    scene_tensors,
    wrong_checkout,
)

from gma.gpu import get_context  # noqa: E402
from gma.render import rasterize  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


def load_peer():
    """The peer's ``render`` function, or None (with the reason printed) when gsplat is missing."""
    import peer_gsplat

    reason = peer_gsplat.missing_reason()
    if reason:
        print(f"peer not measured: {reason}")
        return None
    return peer_gsplat.load()


def gma_step(t: dict, backward: bool, ctx, size) -> None:
    params = [t[k].clone().requires_grad_(backward) for k in ("means", "quats", "scales", "opacities", "colors")]
    out = rasterize(*params, t["viewmat"], t["K"], *size, ctx=ctx)
    if backward:
        out.color.mean().backward()


def peer_step(render, t: dict, backward: bool, size) -> None:
    params = [t[k].clone().requires_grad_(backward) for k in ("means", "quats", "scales3", "opacities", "colors")]
    with torch.set_grad_enabled(backward):
        img = render(*params, t["viewmat"], t["K"], *size)
        if backward:
            img.mean().backward()


# Pause before each timed step: torch's OpenMP workers keep spinning for a while after the peer's last
# op, and the next step would pay for their cores.
SETTLE_S = 0.3


def timed_burst(burst: int, fn, *args) -> list[float]:
    """Wait for the cores to settle, then time ``burst`` calls back to back (ms each)."""
    time.sleep(SETTLE_S)
    times = []
    for _ in range(burst):
        t0 = time.perf_counter()
        fn(*args)
        times.append((time.perf_counter() - t0) * 1e3)
    return times


class Worker(CheckoutWorker):
    """A checkout's GMA in a worker process (this script with ``--worker``, its ``gma`` imported from that
    checkout): each request times one step there."""

    def __init__(self, root: str | Path, n: int, env: dict[str, str] | None = None):
        super().__init__(root, __file__, str(n), env=env)

    def steps(self, backward: bool, burst: int) -> list[float]:
        return [float(v) for v in self.ask(f"{'bwd' if backward else 'fwd'} {burst}").split()]


def worker(n: int) -> int:
    """One side (this checkout or the baseline): time a burst of GMA steps per request on stdin ("fwd K" /
    "bwd K"), print their ms."""
    error = wrong_checkout()
    if error:
        print(error, flush=True)
        return 2
    workload = load_standard_workload()
    ctx = get_context()
    t = scene_tensors(workload, n)
    size = (workload.WIDTH, workload.HEIGHT)
    print(f"ready {ctx.name}", flush=True)
    for line in sys.stdin:
        kind, burst = line.split()
        times = timed_burst(int(burst), gma_step, t, kind == "bwd", ctx, size)
        print(" ".join(f"{v:.3f}" for v in times), flush=True)
    return 0


def _steady(turns: list[list[float]]) -> float:
    """Median of every turn's steps after its first (NaN without turns)."""
    times = [v for turn in turns for v in turn[1:]]
    return statistics.median(times) if times else float("nan")


def _first(turns: list[list[float]]) -> float:
    return statistics.median(turn[0] for turn in turns) if turns else float("nan")


def main() -> int:
    if len(sys.argv) == 3 and sys.argv[1] == "--worker":
        return worker(int(sys.argv[2]))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", type=int, nargs="+", default=[20_000, 100_000])
    ap.add_argument("--repeats", type=int, default=5, help="turns per side")
    ap.add_argument("--burst", type=int, default=3, help="steps per turn, back to back (>= 2)")
    ap.add_argument("--no-peer", action="store_true", help="time GMA only")
    ap.add_argument("--baseline", help="another GMA checkout to time beside this one (a worker process)")
    ap.add_argument("--baseline-env", action="append", metavar="KEY=VALUE",
                    help="KEY=VALUE for the baseline's worker only (repeatable); with --baseline . the "
                         "same code on, e.g., the system's lavapipe: VK_DRIVER_FILES=<its manifest>")
    ap.add_argument("--json", help="also write the results here")
    args = ap.parse_args()
    if args.burst < 2 or args.repeats < 1:
        ap.error("--burst must be >= 2 and --repeats >= 1")
    workload = load_standard_workload()
    render = None if args.no_peer else load_peer()
    ctx = get_context()
    size = (workload.WIDTH, workload.HEIGHT)
    print(f"adapter: {ctx.name}; machine: {machine()}; torch threads: {torch.get_num_threads()}")
    print(f"{'':>25} {'steady (steps 2.. of a turn)':^27} | {'after idle (first step)':^27}")
    print(f"{'N':>7} {'pass':<17} {'GMA ms':>9} {'peer ms':>9} {'ratio':>7} | {'GMA ms':>9} {'peer ms':>9} "
          f"{'ratio':>7}" + (f" {'baseline ms':>12} {'GMA/baseline':>13} {'peer/baseline':>14}" if args.baseline
                             else ""))
    rows = []
    for n in args.counts:
        t = scene_tensors(workload, n)
        ours = Worker(REPO, n)
        base = Worker(args.baseline, n, parse_env(args.baseline_env)) if args.baseline else None
        if n == args.counts[0]:
            print(f"this checkout's worker: {ours.banner}" + (f"; baseline's: {base.banner or 'not reported'}"
                                                               if base else ""))
        for backward in (False, True):
            ours.steps(backward, 1)  # warm-up: pipelines, capacity
            if render:
                peer_step(render, t, backward, size)
            if base:
                base.steps(backward, 1)
            gma, peer, baseline = [], [], []   # one list of step times per turn
            for _ in range(args.repeats):
                gma.append(ours.steps(backward, args.burst))
                if base:
                    baseline.append(base.steps(backward, args.burst))
                if render:
                    peer.append(timed_burst(args.burst, peer_step, render, t, backward, size))
            g, g1 = _steady(gma), _first(gma)
            p, p1 = _steady(peer), _first(peer)
            b = _steady(baseline)
            name = "forward+backward" if backward else "forward"
            print(f"{n:>7} {name:<17} {g:9.1f} {p:9.1f} {p / g:6.1f}x | {g1:9.1f} {p1:9.1f} {p1 / g1:6.1f}x"
                  + (f" {b:12.1f} {g / b:13.2f} {p / b:13.1f}x" if base else ""))
            rows.append({"n": n, "pass": name, "gma_ms": g, "peer_ms": p, "ratio": p / g, "gma_first_ms": g1,
                         "peer_first_ms": p1, "ratio_first": p1 / g1, "gma_runs": gma, "peer_runs": peer,
                         "baseline_ms": b, "baseline_runs": baseline, "ratio_baseline": p / b if base else None})
        ours.close()
        if base:
            base.close()
    print(f"load after: {machine()}")
    if args.json:
        Path(args.json).write_text(json.dumps({"adapter": ctx.name, "machine": machine(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
