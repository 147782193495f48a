#!/usr/bin/env python3
"""How the driver shares a compute dispatch between its CPU threads, and what the tile walks' tile order
(``walk_tile`` in shaders/wgsl/render/rasterize_core.wgsl) makes of it.

1. A probe kernel: W workgroups, half of them looping ``--heavy`` times and the rest 10 times, the heavy
   half either first (workgroups 0..W/2) or every other workgroup. A driver that hands out workgroups one
   at a time takes about as long for both; lavapipe, which gives each of its N threads one contiguous run
   of ~W/N workgroups, takes about twice as long when the heavy half comes first.
2. A scene's tile lists: the share of its intersections that falls into the busiest thread's run when
   workgroup w replays tile w (row order) and in walk_tile's order, for the driver's thread count
   (``GpuContext.dispatch_threads``). A tile walk lasts about as long as its busiest thread.

    python benchmarks/dispatch_split.py [--workgroups 1024] [--heavy 20000] [--repeats 5]
                                        [--scene avatar|standard] [--count 100000] [--size 512]
"""

from __future__ import annotations

import argparse
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import wgpu

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, scene_and_camera  # noqa: E402

from gma.gpu import get_context  # noqa: E402
from gma.render import SurfelRasterizer  # noqa: E402
from gma.render.layouts import tile_grid  # noqa: E402
from gma.render.surfels import SurfelBuffers  # noqa: E402

PROBE = """
@group(0) @binding(0) var<storage, read_write> out: array<f32>;
@group(0) @binding(1) var<uniform> setup: vec4<u32>;   // heavy first?, workgroups, heavy loop trips
@compute @workgroup_size(8)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let heavy = select((wg.x % 2u) == 0u, wg.x < setup.y / 2u, setup.x == 1u);
    var x = f32(lid);
    for (var i = 0u; i < select(10u, setup.z, heavy); i++) {
        x = x * 0.999 + 0.5;
    }
    out[wg.x * 8u + lid] = x;
}
"""


def probe_ms(ctx, workgroups: int, heavy: int, repeats: int) -> dict[str, float]:
    """Median ms of the probe dispatch with the heavy half first and interleaved."""
    pipeline = ctx.device.create_compute_pipeline(
        layout=wgpu.AutoLayoutMode.auto,
        compute={"module": ctx.device.create_shader_module(code=PROBE), "entry_point": "main"})
    out = ctx.buffer(32 * workgroups, "probe.out")
    result = {}
    for name, first in (("heavy half first", 1), ("heavy every other", 0)):
        setup = ctx.upload(np.array([first, workgroups, heavy, 0], np.uint32), "probe.setup",
                           wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
        group = ctx.bind_group(pipeline, [out, setup])
        times = []
        for _ in range(repeats + 1):   # the first compiles and warms up
            enc = ctx.device.create_command_encoder()
            cp = enc.begin_compute_pass()
            cp.set_pipeline(pipeline)
            cp.set_bind_group(0, group)
            cp.dispatch_workgroups(workgroups)
            cp.end()
            t0 = time.perf_counter()
            ctx.submit(enc)
            ctx.wait_idle()
            times.append((time.perf_counter() - t0) * 1e3)
        result[name] = statistics.median(times[1:])
    return result


def walk_order(tiles_x: int, tiles_y: int, threads: int) -> np.ndarray:
    """walk_tile's tile for every workgroup (numpy mirror of the WGSL function)."""
    tiles = tiles_x * tiles_y
    w = np.arange(tiles)
    q = tiles // threads
    if q == 0:
        return w
    s = math.gcd(q, tiles_x)
    k = w % q
    return np.where(w < q * threads, ((k // s) * threads + w // q) * s + k % s, w)


def busiest_share(hits_by_workgroup: np.ndarray, threads: int) -> float:
    """The busiest thread's share of the hits when each of ``threads`` takes one contiguous run of
    workgroups (the first threads * (W // threads) in equal runs, the rest one each, shared out evenly)."""
    per = len(hits_by_workgroup) // threads
    runs = [hits_by_workgroup[i * per:(i + 1) * per].sum() for i in range(threads)]
    for k, extra in enumerate(hits_by_workgroup[per * threads:]):
        runs[k % threads] += extra
    return float(max(runs) / max(hits_by_workgroup.sum(), 1))


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--workgroups", type=int, default=1024)
    p.add_argument("--heavy", type=int, default=20000, help="loop trips of a heavy workgroup")
    p.add_argument("--repeats", type=int, default=5)
    p.add_argument("--scene", choices=("standard", "avatar"), default="avatar")
    p.add_argument("--count", type=int, default=100000, help="surfels of the scene")
    p.add_argument("--size", type=int, default=512, help="image side of the avatar scene")
    args = p.parse_args()
    for name, value, low, high in (("--workgroups", args.workgroups, 2, 65535), ("--heavy", args.heavy, 1, 10**7),
                                   ("--repeats", args.repeats, 1, 1000), ("--count", args.count, 1, 10**7),
                                   ("--size", args.size, 16, 4096)):
        if not low <= value <= high:
            print(f"{name} {value}: must lie in {low}..{high}", file=sys.stderr)
            return 2
    ctx = get_context()
    threads = ctx.dispatch_threads
    print(f"adapter: {ctx.name}; {machine()}; threads splitting a dispatch (as GMA assumes): {threads}")
    times = probe_ms(ctx, args.workgroups, args.heavy, args.repeats)
    first, interleaved = times["heavy half first"], times["heavy every other"]
    print(f"probe, {args.workgroups} workgroups: heavy half first {first:.2f} ms, heavy every other "
          f"{interleaved:.2f} ms ({first / interleaved:.2f}x)")

    scene, cam = scene_and_camera(args.count, args.scene, args.size)
    rast = SurfelRasterizer(ctx)
    surfels = SurfelBuffers.from_arrays(ctx, *(np.ascontiguousarray(scene[k], np.float32) for k in
                                               ("means", "quats", "scales", "opacities", "colors")))
    state = rast.forward(surfels, cam, replay=False)
    tx, ty = tile_grid(cam.width, cam.height)
    ranges = ctx.read_many([(state.tile_ranges, np.uint32, 2 * tx * ty)])[0].reshape(-1, 2).astype(np.int64)
    hits = ranges[:, 1] - ranges[:, 0]
    for n in sorted({2, threads}):
        row = busiest_share(hits, n)
        walked = busiest_share(hits[walk_order(tx, ty, n)], n)
        print(f"{args.scene} scene, {int(hits.sum())} intersections in {tx}x{ty} tiles, {n} threads: busiest "
              f"thread's share {row:.1%} in row order, {walked:.1%} in walk_tile's (even: {1 / n:.1%})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
