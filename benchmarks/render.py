#!/usr/bin/env python3
"""Forward renderer figures (issue 2): avatar-like surfels at 512^2 and 1024^2, the standard comparison
scene, per-pass GPU times, candidate surfel-pixel evaluations per second, and the speed-up over the torch
reference. Prints a table; ``--json`` also writes the numbers.

    python benchmarks/render.py [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import add_scene_args, load_standard_workload, machine, median_dict, workload_surfels  # noqa: E402

from gma.gpu import PassTimer, get_context  # noqa: E402
from gma.render import SurfelBuffers, SurfelRasterizer, rasterize_reference, read_outputs  # noqa: E402
from gma.render.scenes import avatar_camera, avatar_like_scene  # noqa: E402


def bench_forward(ctx, rast, scene, cam, repeats):
    buffers = SurfelBuffers.from_arrays(ctx, scene["means"], scene["quats"], scene["scales"], scene["opacities"],
                                        scene["colors"])
    walls, passes, isects = [], [], 0
    for i in range(repeats + 1):
        timer = PassTimer(ctx, 256)
        t0 = time.perf_counter()
        state = rast.forward(buffers, cam, None, timer)
        read_outputs(ctx, state)
        wall = (time.perf_counter() - t0) * 1e3
        if i:  # the first run compiles pipelines
            walls.append(wall)
            passes.append(timer.results())
        isects = state.num_isects
    return float(np.median(walls)), median_dict(passes), isects


def reference_ms(scene, cam, n_ref):
    t = {k: torch.from_numpy(v[:n_ref]) for k, v in scene.items()}
    t0 = time.perf_counter()
    rasterize_reference(t["means"], t["quats"], t["scales"], t["opacities"], t["colors"],
                        torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height)
    return (time.perf_counter() - t0) * 1e3


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--sizes", type=int, nargs="+", default=[512, 1024])
    ap.add_argument("--counts", type=int, nargs="+", default=[50_000, 200_000])
    add_scene_args(ap, reference_count=5000, reference_size=128)
    ap.add_argument("--json", help="also write the results here")
    args = ap.parse_args()
    ctx = get_context()
    rast = SurfelRasterizer(ctx)
    print(f"adapter: {ctx.name}; machine: {machine()}; options: {rast.options}")
    rows = []
    cases = [(f"avatar {n // 1000}k", avatar_like_scene(n), avatar_camera(s, s)) for n in args.counts
             for s in args.sizes]
    workload = load_standard_workload()
    for n in args.standard_counts:
        scene, cam = workload_surfels(workload, n)
        cases.append((f"standard {n / 1000:g}k", scene, cam))
    print(f"{'scene':<14} {'size':>9} {'frame ms':>9} {'isects':>9} {'Meval/s':>8}  per pass (GPU ms)")
    for name, scene, cam in cases:
        wall, passes, isects = bench_forward(ctx, rast, scene, cam, args.repeats)
        evals = isects * 256  # every intersection is tested against every pixel of its tile
        rows.append({"scene": name, "width": cam.width, "height": cam.height, "frame_ms": wall, "isects": isects,
                     "candidate_evals_per_s": evals / (wall / 1e3), "passes_ms": passes})
        per_pass = ", ".join(f"{k} {v:.1f}" for k, v in passes.items())
        size = f"{cam.width}x{cam.height}"
        print(f"{name:<14} {size:>9} {wall:9.1f} {isects:9d} {evals / wall / 1e3:8.0f}  {per_pass}")
    # Speed-up over the reference at a size it can finish (it evaluates every surfel at every pixel).
    n_ref, size = args.reference_count, args.reference_size
    scene, cam = avatar_like_scene(n_ref), avatar_camera(size, size)
    ref = reference_ms(scene, cam, n_ref)
    wall, _, _ = bench_forward(ctx, rast, scene, cam, args.repeats)
    print(f"torch reference, {n_ref} surfels at {size}x{size}: {ref:.0f} ms vs WGSL {wall:.1f} ms: "
          f"{ref / wall:.0f}x faster")
    rows.append({"scene": f"reference-comparison {n_ref / 1000:g}k", "reference_ms": ref, "wgsl_ms": wall,
                 "speedup": ref / wall})
    if args.json:
        Path(args.json).write_text(json.dumps({"adapter": ctx.name, "machine": machine(), "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
