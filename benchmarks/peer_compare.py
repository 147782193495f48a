#!/usr/bin/env python3
"""GMA against the comparison peer in one run (issue 15): the standard scene (../shared/bench), rendered
through the public ``gma.render.rasterize`` call as a user would (upload, render, read back, torch tensors),
and through gsplat 1.5.3's pure-PyTorch 2DGS path (``../shared/bench/peer_gsplat_torch.py``), both at
torch's default thread count. Runs alternate (GMA, peer, GMA, peer, ...) so that a machine whose speed
drifts affects both sides alike. Prints medians and the ratios.

    BUILD_NO_CUDA=1 pip install gsplat==1.5.3     # once: the peer
    python benchmarks/peer_compare.py [--counts 20000 100000] [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import statistics
import sys
import time
from pathlib import Path

import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import SHARED_WORKLOAD, load_standard_workload, machine  # noqa: E402

from gma.gpu import get_context  # noqa: E402
from gma.render import rasterize  # noqa: E402

PEER = SHARED_WORKLOAD.parent / "peer_gsplat_torch.py"


def load_peer():
    """The peer's ``render`` function, or None (with the reason printed) when gsplat or the script is missing."""
    if not PEER.is_file():
        print(f"peer script not found: {PEER}")
        return None
    if importlib.util.find_spec("gsplat") is None:
        print("gsplat is not installed: BUILD_NO_CUDA=1 pip install gsplat==1.5.3")
        return None
    sys.path.insert(0, str(PEER.parent))
    spec = importlib.util.spec_from_file_location("peer_gsplat_torch", PEER)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.render


def scene_tensors(workload, n: int) -> dict:
    w = workload.make_workload(n)
    t = {k: torch.from_numpy(w[k]) for k in ("means", "quats", "opacities", "colors", "viewmat", "K")}
    t["scales3"] = torch.from_numpy(w["scales_2d"])  # the peer's 2DGS layout: third scale 0
    t["scales"] = t["scales3"][:, :2].contiguous()
    return t


def gma_step(t: dict, backward: bool, ctx, size) -> None:
    params = [t[k].clone().requires_grad_(backward) for k in ("means", "quats", "scales", "opacities", "colors")]
    out = rasterize(*params, t["viewmat"], t["K"], *size, ctx=ctx)
    if backward:
        out.color.mean().backward()


def peer_step(render, t: dict, backward: bool, size) -> None:
    params = [t[k].clone().requires_grad_(backward) for k in ("means", "quats", "scales3", "opacities", "colors")]
    with torch.set_grad_enabled(backward):
        img = render("2dgs", *params, t["viewmat"], t["K"], *size)
        if backward:
            img.mean().backward()


def timed(fn, *args) -> float:
    t0 = time.perf_counter()
    fn(*args)
    return (time.perf_counter() - t0) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--counts", type=int, nargs="+", default=[20_000, 100_000])
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--no-peer", action="store_true", help="time GMA only")
    ap.add_argument("--json", help="also write the results here")
    args = ap.parse_args()
    workload = load_standard_workload()
    if workload is None:
        print(f"standard workload not found ({SHARED_WORKLOAD}): nothing to compare")
        return 0
    render = None if args.no_peer else load_peer()
    ctx = get_context()
    size = (workload.WIDTH, workload.HEIGHT)
    print(f"adapter: {ctx.name}; machine: {machine()}; torch threads: {torch.get_num_threads()}")
    print(f"{'N':>7} {'pass':<17} {'GMA ms':>9} {'peer ms':>9} {'ratio':>7}")
    rows = []
    for n in args.counts:
        t = scene_tensors(workload, n)
        for backward in (False, True):
            gma_step(t, backward, ctx, size)  # warm-up: pipelines, capacity
            if render:
                peer_step(render, t, backward, size)
            gma, peer = [], []
            for _ in range(args.repeats):
                gma.append(timed(gma_step, t, backward, ctx, size))
                if render:
                    peer.append(timed(peer_step, render, t, backward, size))
            g = statistics.median(gma)
            p = statistics.median(peer) if peer else float("nan")
            name = "forward+backward" if backward else "forward"
            print(f"{n:>7} {name:<17} {g:9.1f} {p:9.1f} {p / g:6.1f}x")
            rows.append({"n": n, "pass": name, "gma_ms": g, "peer_ms": p, "ratio": p / g, "gma_runs": gma,
                         "peer_runs": peer})
    print(f"load after: {machine()}")
    if args.json:
        Path(args.json).write_text(json.dumps({"adapter": ctx.name, "machine": machine(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
