"""Figures for the body issue: time to create the default (Anny) body, cold and warm cache, and per-frame
posing of the default body with N surfels per face, torch path vs WGSL path (median ms).

    python benchmarks/body_posing.py [--per-face 8] [--frames 30] [--cold]

``--cold`` builds anny's cache from scratch in a temporary directory (a minute or more and ~1 GB of
disk); without it the cold figure is skipped. Each creation runs in a fresh subprocess so
that neither Python's nor anny's in-process caches help.

Per-frame work measured:
- torch:  bone transforms (forward kinematics) + LBS + surfel placement, all in torch on the CPU;
- wgsl:   bone transforms in torch, upload of J×48 bytes, skinning + placement on the GPU, waiting for
          the GPU to finish through a 4-byte readback (the viewer would not wait; this is the latency);
- fk:     the forward kinematics alone (shared by both paths).
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time

from gma.body.anny_body import DEFAULT_ANNY_CACHE_DIR

CREATE_SNIPPET = (
    "import time; t = time.perf_counter(); from gma.body import load_body; load_body('anny'); "
    "print(time.perf_counter() - t)"
)


def time_creation(cache_dir: str) -> float:
    env = dict(os.environ, ANNY_CACHE_DIR=cache_dir)
    out = subprocess.run([sys.executable, "-c", CREATE_SNIPPET], env=env, check=True, capture_output=True,
                         text=True)
    return float(out.stdout.strip().splitlines()[-1])


def median_ms(fn, frames: int) -> float:
    fn(0)  # warm-up: first-call allocations, pipeline creation
    times = []
    for i in range(frames):
        t = time.perf_counter()
        fn(i)
        times.append((time.perf_counter() - t) * 1e3)
    return statistics.median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--per-face", type=int, default=8, help="surfels per face")
    ap.add_argument("--frames", type=int, default=30, help="frames timed per path")
    ap.add_argument("--cold", action="store_true", help="also time creation with an empty anny cache")
    args = ap.parse_args()
    cache = os.environ.get("ANNY_CACHE_DIR", str(DEFAULT_ANNY_CACHE_DIR))

    if args.cold:
        with tempfile.TemporaryDirectory(prefix="anny-cold-") as d:
            print(f"create default body, cold cache: {time_creation(d):8.1f} s")
    print(f"create default body, warm cache: {time_creation(cache):8.2f} s  (new process)")

    import torch

    from gma.body import load_body, place_surfels, uniform_surfels
    from gma.body.gpu_posing import GpuPoser
    from gma.body.motions import motion
    from gma.body.skinning import linear_blend_skinning
    from gma.gpu import get_context

    torch.set_grad_enabled(False)
    body = load_body("anny")
    walk = motion("walk", 60, body)
    binding = uniform_surfels(body.num_faces, args.per_face)
    rest = body.rest_vertices({})
    n = len(binding)
    print(f"default body: V={body.num_vertices} F={body.num_faces} J={body.num_bones} "
          f"K={body.skin_indices.shape[1]}, surfels N={n} ({args.per_face}/face), torch threads "
          f"{torch.get_num_threads()}")

    def fk(i):
        return body.bone_transforms(walk.params(i))

    def torch_path(i):
        posed = linear_blend_skinning(rest, body.skin_indices, body.skin_weights, fk(i))
        return place_surfels(posed, body.faces, binding)

    ctx = get_context()
    poser = GpuPoser(ctx, body.faces, body.skin_indices, body.skin_weights)
    poser.set_rest_vertices(rest)
    poser.set_surfels(binding)
    outs = poser.output_buffers()
    transforms = [fk(i) for i in range(len(walk))]

    def sync():
        # A 4-byte readback waits for the queue (on_submitted_work_done_sync is broken in wgpu 0.32).
        ctx.read(outs[2], "f4", 1)

    def wgsl_path(i):
        poser.pose(fk(i), *outs)
        sync()

    def wgsl_gpu_only(i):
        poser.pose(transforms[i % len(transforms)], *outs)
        sync()

    t_fk = median_ms(fk, args.frames)
    t_torch = median_ms(torch_path, args.frames)
    t_wgsl = median_ms(wgsl_path, args.frames)
    t_gpu = median_ms(wgsl_gpu_only, args.frames)
    print(f"device: {ctx.name}")
    print(f"forward kinematics (torch, shared): {t_fk:8.2f} ms")
    print(f"torch path  (fk + LBS + placement):  {t_torch:8.2f} ms")
    print(f"WGSL path   (fk + upload + GPU):     {t_wgsl:8.2f} ms")
    print(f"WGSL passes (upload + GPU, no fk):   {t_gpu:8.2f} ms")
    print(f"torch / WGSL: {t_torch / t_wgsl:.1f}x")


if __name__ == "__main__":
    main()
