#!/usr/bin/env python3
"""Forward+backward figures (issue 3): avatar-like surfels at 512^2 (50k, 200k) and the standard comparison
scene (loss = mean of the image), per pass (GPU timestamps), host<->GPU transfer time and bytes, GPU memory
allocated per step, peak process memory, and the speed-up over the torch reference's forward+backward.

    python benchmarks/render_backward.py [--repeats 5] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import resource
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import add_scene_args, load_standard_workload, machine, median_dict, workload_surfels  # noqa: E402

from gma.gpu import PassTimer, get_context  # noqa: E402
from gma.render import Camera, rasterize, rasterize_reference  # noqa: E402
from gma.render.scenes import avatar_camera, avatar_like_scene  # noqa: E402

NAMES = ("means", "quats", "scales", "opacities", "colors")


def step(ctx, scene: dict[str, torch.Tensor], cam: Camera, timer=None):
    """One training-like step: forward, loss = mean colour, backward. Returns per-phase wall ms."""
    inputs = {k: v.clone().requires_grad_(True) for k, v in scene.items()}
    view, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)
    t0 = time.perf_counter()
    out = rasterize(*(inputs[k] for k in NAMES), view, K, cam.width, cam.height, ctx=ctx)
    t1 = time.perf_counter()
    out.color.mean().backward()
    t2 = time.perf_counter()
    return {"forward": (t1 - t0) * 1e3, "backward": (t2 - t1) * 1e3, "total": (t2 - t0) * 1e3}


def bench(ctx, name, scene_np, cam, repeats):
    scene = {k: torch.from_numpy(v) for k, v in scene_np.items()}
    step(ctx, scene, cam)  # compile pipelines
    walls, transfers = [], []
    ctx.transfers.wait_for_compute = True   # download times without the compute queued before them
    alloc0 = ctx.allocated_bytes
    for _ in range(repeats):
        ctx.transfers.reset()
        walls.append(step(ctx, scene, cam))
        t = ctx.transfers
        transfers.append({"up_ms": t.seconds_up * 1e3, "down_ms": t.seconds_down * 1e3,
                          "up_MB": t.bytes_up / 1e6, "down_MB": t.bytes_down / 1e6})
    alloc_per_step = (ctx.allocated_bytes - alloc0) / repeats / 1e6
    # GPU per-pass times, from one more step with timestamps on the rasterizer's own passes.
    from gma.render.api import rasterizer_for
    from gma.render.surfels import SurfelBuffers

    rast = rasterizer_for(ctx)
    passes = []
    buffers = SurfelBuffers.from_arrays(ctx, *(scene_np[k] for k in NAMES))
    hw = cam.width * cam.height
    v_color = np.full((hw, scene_np["colors"].shape[1]), 1.0 / (hw * scene_np["colors"].shape[1]), np.float32)
    for _ in range(max(1, repeats // 2)):
        timer = PassTimer(ctx, 256)
        state = rast.forward(buffers, cam, None, timer)
        rast.backward(state, buffers, v_color, None, None, None, timer)
        passes.append(timer.results())
    row = {"scene": name, "size": f"{cam.width}x{cam.height}", "wall_ms": median_dict(walls),
           "transfers": median_dict(transfers), "gpu_passes_ms": median_dict(passes),
           "gpu_alloc_MB_per_step": alloc_per_step}
    w, tr = row["wall_ms"], row["transfers"]
    passes_txt = ", ".join(f"{k} {v:.1f}" for k, v in row["gpu_passes_ms"].items())
    print(f"{name:<14} {row['size']:>9} fwd {w['forward']:7.1f}  bwd {w['backward']:7.1f}  total {w['total']:7.1f} ms"
          f" | transfers up {tr['up_MB']:.1f} MB {tr['up_ms']:.1f} ms, down {tr['down_MB']:.1f} MB {tr['down_ms']:.1f}"
          f" ms | GPU alloc {alloc_per_step:.0f} MB/step\n{'':>25}GPU passes: {passes_txt}")
    return row


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--counts", type=int, nargs="+", default=[50_000, 200_000])
    add_scene_args(ap, reference_count=3000, reference_size=96)
    ap.add_argument("--json")
    args = ap.parse_args()
    torch.set_num_threads(1)  # lavapipe needs the cores; torch only glues here
    ctx = get_context()
    print(f"adapter: {ctx.name}; machine: {machine()}")
    rows = [bench(ctx, f"avatar {n // 1000}k", avatar_like_scene(n), avatar_camera(512, 512), args.repeats)
            for n in args.counts]
    workload = load_standard_workload()
    for n in args.standard_counts:
        scene, cam = workload_surfels(workload, n)
        rows.append(bench(ctx, f"standard {n / 1000:g}k", scene, cam, args.repeats))
    # Reference forward+backward at a size it can finish.
    n_ref, size = args.reference_count, args.reference_size
    scene_np, cam = avatar_like_scene(n_ref), avatar_camera(size, size)
    t = {k: torch.from_numpy(v).requires_grad_(True) for k, v in scene_np.items()}
    t0 = time.perf_counter()
    ref = rasterize_reference(*(t[k] for k in NAMES), torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K),
                              cam.width, cam.height)
    ref["color"].mean().backward()
    ref_ms = (time.perf_counter() - t0) * 1e3
    ours = bench(ctx, f"ref-size {n_ref / 1000:g}k", scene_np, cam, args.repeats)["wall_ms"]["total"]
    print(f"torch reference fwd+bwd, {n_ref} surfels at {size}x{size}: {ref_ms:.0f} ms vs WGSL {ours:.1f} ms: "
          f"{ref_ms / ours:.0f}x")
    peak_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"peak process memory (RSS, lavapipe's GPU memory included): {peak_mb:.0f} MB")
    if args.json:
        Path(args.json).write_text(json.dumps({"adapter": ctx.name, "machine": machine(), "rows": rows,
                                               "reference_ms": ref_ms, "peak_rss_MB": peak_mb}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
