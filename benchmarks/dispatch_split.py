#!/usr/bin/env python3
"""How the driver shares a compute dispatch between its CPU threads, and what the renderer's work queues
(shaders/wgsl/common/work_queue.wgsl) make of it.

1. A probe kernel: W work items, half of them looping ``--heavy`` times and the rest 10 times, the heavy
   half either first (items 0..W/2) or every other item, run as one workgroup per item and, with
   subgroups, as one workgroup per driver thread taking items from a queue (``take_work``). A driver that
   hands out workgroups one at a time takes about as long for both orders; lavapipe, which gives each of
   its N threads one contiguous run of ~W/N workgroups, takes about twice as long when the heavy half
   comes first, unless the items come from the queue.
2. A scene's tile lists: the share of its intersections that falls into the busiest thread's run when
   workgroup w replays tile w (row order), for the driver's thread count (``GpuContext.dispatch_threads``).
   Without a queue a tile walk lasts about as long as its busiest thread.

    python benchmarks/dispatch_split.py [--workgroups 1024] [--heavy 20000] [--repeats 5]
                                        [--scene avatar|standard] [--count 100000] [--size 512]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np
import wgpu

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine, scene_and_camera  # noqa: E402

from gma.gpu import get_context  # noqa: E402
from gma.gpu.shaders import ShaderLibrary  # noqa: E402
from gma.render import SurfelRasterizer  # noqa: E402
from gma.render.layouts import tile_grid  # noqa: E402
from gma.render.surfels import SurfelBuffers  # noqa: E402

PROBE = """
@group(0) @binding(0) var<storage, read_write> out: array<f32>;
@group(0) @binding(1) var<uniform> setup: vec4<u32>;   // heavy first?, workgroups, heavy loop trips

fn item(w: u32, lid: u32) {
    let heavy = select((w % 2u) == 0u, w < setup.y / 2u, setup.x == 1u);
    var x = f32(lid);
    for (var i = 0u; i < select(10u, setup.z, heavy); i++) {
        x = x * 0.999 + 0.5;
    }
    out[w * 8u + lid] = x;
}

#if WORK_QUEUE
@group(0) @binding(2) var<storage, read_write> work_queue: array<atomic<u32>>;
#include "common/work_queue.wgsl"

@compute @workgroup_size(8)
fn main(@builtin(subgroup_invocation_id) sg_lane: u32, @builtin(local_invocation_index) lid: u32) {
    loop {
        let w = take_work(1u, sg_lane);
        if w >= setup.y {
            break;
        }
        item(w, lid);
    }
}
#else
@compute @workgroup_size(8)
fn main(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    item(wg.x, lid);
}
#endif
"""


def probe_ms(ctx, workgroups: int, heavy: int, repeats: int) -> dict[str, float]:
    """Median ms of the probe with the heavy half first and interleaved, one workgroup per item, and with
    the heavy half first from a queue (where the adapter has subgroups)."""
    library = ShaderLibrary()
    out = ctx.buffer(32 * workgroups, "probe.out")
    counter = ctx.buffer(16, "probe.queue")
    result = {}
    runs = [("heavy half first", 1, False), ("heavy every other", 0, False)]
    if ctx.has_subgroups:
        runs.append(("heavy half first, queued", 1, True))
    for name, first, queued in runs:
        code = library.source_text(PROBE, {"WORK_QUEUE": queued})
        pipeline = ctx.device.create_compute_pipeline(
            layout=wgpu.AutoLayoutMode.auto,
            compute={"module": ctx.device.create_shader_module(code=code), "entry_point": "main"})
        setup = ctx.upload(np.array([first, workgroups, heavy, 0], np.uint32), "probe.setup",
                           wgpu.BufferUsage.UNIFORM | wgpu.BufferUsage.COPY_DST)
        group = ctx.bind_group(pipeline, [out, setup] + ([counter] if queued else []))
        times = []
        for _ in range(repeats + 1):   # the first compiles and warms up
            enc = ctx.device.create_command_encoder()
            if queued:
                enc.clear_buffer(counter, 0, 16)
            cp = enc.begin_compute_pass()
            cp.set_pipeline(pipeline)
            cp.set_bind_group(0, group)
            cp.dispatch_workgroups(ctx.dispatch_threads if queued else workgroups)
            cp.end()
            t0 = time.perf_counter()
            ctx.submit(enc)
            ctx.wait_idle()
            times.append((time.perf_counter() - t0) * 1e3)
        result[name] = statistics.median(times[1:])
    return result


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
    queued = times.get("heavy half first, queued")
    print(f"probe, {args.workgroups} items: heavy half first {first:.2f} ms, heavy every other "
          f"{interleaved:.2f} ms ({first / interleaved:.2f}x)"
          + (f"; heavy half first from a queue {queued:.2f} ms ({queued / interleaved:.2f}x)" if queued else ""))

    scene, cam = scene_and_camera(args.count, args.scene, args.size)
    rast = SurfelRasterizer(ctx)
    surfels = SurfelBuffers.from_arrays(ctx, *(np.ascontiguousarray(scene[k], np.float32) for k in
                                               ("means", "quats", "scales", "opacities", "colors")))
    state = rast.forward(surfels, cam, replay=False)
    tx, ty = tile_grid(cam.width, cam.height)
    ranges = ctx.read_many([(state.tile_ranges, np.uint32, 2 * tx * ty)])[0].reshape(-1, 2).astype(np.int64)
    hits = ranges[:, 1] - ranges[:, 0]
    for n in sorted({2, threads}):
        print(f"{args.scene} scene, {int(hits.sum())} intersections in {tx}x{ty} tiles, {n} threads: busiest "
              f"thread's share {busiest_share(hits, n):.1%} in row order (even: {1 / n:.1%})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
