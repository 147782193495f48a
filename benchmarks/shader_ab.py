#!/usr/bin/env python3
"""Two versions of the WGSL shaders against each other in one process, for shader work on a machine whose
speed drifts (a shared virtual machine's passes can swing within minutes by more than most shader
changes win). Each round renders the standard scene (forward, then backward with a random colour gradient) once
with each shader directory, in alternating order, through one rasterizer per directory; a round's
GPU pass times are compared directly. Prints per pass the medians and the median of the per-round ratios
B / A, and the images' and gradients' sums (equal sums: the change kept them, very likely bit for bit).

    cp -r shaders/wgsl /tmp/a && cp -r shaders/wgsl /tmp/b   # then edit /tmp/b
    python benchmarks/shader_ab.py /tmp/a /tmp/b [--rounds 16] [--count 100000] [--scene avatar] [--size 512]

Only the shaders differ: the Python side is this checkout's. ``--toggle OPTION`` instead renders with this
checkout's shaders both times and two rasterizers whose ``RasterOptions`` differ in one switch, off (A) and
on (B), the rest as the adapter's defaults (switching ``subgroups`` or ``tile_walk`` off also switches off
what needs them), e.g. ``python benchmarks/shader_ab.py --toggle work_queues --scene avatar``.
``--scene avatar`` renders avatar-like surfels instead of the standard scene (small, tangent to a
body-shaped surface; gma.render.scenes) at --size pixels square.

``--public`` times whole steps of the public call instead (``gma.render.rasterize``, the mean colour's
backward, as ``peer_compare.py`` times them), alternating the directories' pipelines under the context's
one rasterizer, two timed steps per directory and round after an untimed one; prints the medians, the
median of the per-step ratios B / A, and the means' gradient sums. Two identical directories read
within a few percent of 1.00x, so it shows changes of the whole step above that; the pass times above
resolve smaller ones.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import PASSES, machine, pass_inputs, scene_and_camera  # noqa: E402

from gma.gpu import PassTimer, get_context  # noqa: E402
from gma.gpu.shaders import ShaderLibrary, shader_root  # noqa: E402
from gma.render import RasterOptions, SurfelRasterizer, read_outputs  # noqa: E402
from gma.render.rasterizer import MAX_SURFELS  # noqa: E402


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("a", nargs="?", help="shader directory A (like shaders/wgsl)")
    p.add_argument("b", nargs="?", help="shader directory B")
    p.add_argument("--toggle", metavar="OPTION", help="a RasterOptions switch, off in A and on in B (no directories)")
    p.add_argument("--rounds", type=int, default=16)
    p.add_argument("--count", type=int, default=100000, help="surfels of the scene")
    p.add_argument("--scene", choices=("standard", "avatar"), default="standard")
    p.add_argument("--size", type=int, default=512, help="image side of the avatar scene")
    p.add_argument("--public", action="store_true", help="time public forward+backward steps (directories only)")
    args = p.parse_args()
    if args.rounds < 1:
        print(f"--rounds {args.rounds}: needs at least 1", file=sys.stderr)
        return 2
    if not 16 <= args.size <= 4096:
        print(f"--size {args.size}: must lie in 16..4096", file=sys.stderr)
        return 2
    if not 1 <= args.count <= MAX_SURFELS:
        print(f"--count {args.count}: must lie in 1..{MAX_SURFELS} (the renderer's surfel limit)", file=sys.stderr)
        return 2
    two_dirs = args.a is not None and args.b is not None
    no_dirs = args.a is None and args.b is None
    if not ((args.toggle is None and two_dirs) or (args.toggle is not None and no_dirs)):
        print("give two shader directories, or --toggle OPTION without them", file=sys.stderr)
        return 2
    if args.public and args.toggle:
        print("--public compares two shader directories, not a --toggle", file=sys.stderr)
        return 2
    if args.public and args.rounds < 2:   # the first round only warms up
        print(f"--rounds {args.rounds}: --public needs at least 2", file=sys.stderr)
        return 2
    dirs = [shader_root()] * 2 if args.toggle else [Path(args.a), Path(args.b)]
    if args.toggle and args.toggle not in SWITCHES:
        print(f"--toggle {args.toggle}: not a switch of RasterOptions ({', '.join(SWITCHES)})", file=sys.stderr)
        return 2
    for d in dirs:
        if not (d / "render" / "rasterize_fwd.wgsl").is_file():
            print(f"{d}: not a shader directory (no render/rasterize_fwd.wgsl)", file=sys.stderr)
            return 2
    ctx = get_context()
    print(f"adapter: {ctx.name}; {machine()}")
    scene, cam = scene_and_camera(args.count, args.scene, args.size)
    if args.public:
        return public_steps(ctx, [(ShaderLibrary(d), {}) for d in dirs], scene, cam, args.rounds)
    surfels, upstream = pass_inputs(ctx, scene, cam)
    # Each directory gets its own shader library and pipeline cache; the context switches between them.
    try:
        options = [toggled(ctx, args.toggle, on) for on in (False, True)] if args.toggle else [None, None]
    except ValueError as e:   # a switch this adapter cannot turn on
        print(f"--toggle {args.toggle}: {e}", file=sys.stderr)
        return 2
    setups = [(ShaderLibrary(d), {}, SurfelRasterizer(ctx, o)) for d, o in zip(dirs, options)]
    timer = PassTimer(ctx)
    times: list[list[dict]] = [[], []]
    sums: list[tuple] = [(), ()]
    warmup = min(2, max(args.rounds - 1, 0))
    for r in range(args.rounds):
        for i in (0, 1) if r % 2 == 0 else (1, 0):
            ctx.shaders, ctx._pipelines, rast = setups[i]
            state = rast.forward(surfels, cam, timer=timer)
            out = read_outputs(ctx, state)
            passes = timer.results()
            grads = rast.backward(state, surfels, upstream, None, None, None, timer=timer)
            passes.update(timer.results())
            if r >= warmup:
                times[i].append(passes)
            sums[i] = (float(out.color.sum()), float(np.abs(grads.means).sum()), float(np.abs(grads.colors).sum()))
    print(f"{'pass':14s} {'A ms':>8s} {'B ms':>8s} {'B/A':>7s}  (median of per-round ratios, {len(times[0])} rounds)")
    for name in PASSES:
        a = np.array([t.get(name, 0.0) for t in times[0]])
        b = np.array([t.get(name, 0.0) for t in times[1]])
        if a.size and a.min() > 0:
            print(f"{name:14s} {np.median(a):8.2f} {np.median(b):8.2f} {np.median(b / a):7.3f}")
    print(f"sums (colour, |d means|, |d colours|): A {sums[0]}\n{'':38s}B {sums[1]}")
    return 0


SWITCHES = tuple(f.name for f in dataclasses.fields(RasterOptions) if f.type in (bool, "bool"))
# Switched off with the switch they need.
NEEDS = {"subgroups": ("tile_walk", "grad_records"), "tile_walk": ("grad_records",)}


def toggled(ctx, name: str, on: bool) -> RasterOptions:
    """The adapter's options with switch ``name`` set to ``on`` (off: also what needs it); ValueError when
    the adapter cannot run that."""
    changes = {name: on} if on else {name: False, **dict.fromkeys(NEEDS.get(name, ()), False)}
    options = dataclasses.replace(RasterOptions.for_context(ctx), **changes)
    options.check(ctx)
    return options


def public_steps(ctx, setups, scene: dict, cam, rounds: int) -> int:
    """``--public``: forward+backward steps of the public call, the directories' pipelines alternating."""
    import torch

    from gma.render import rasterize

    tensors = {k: torch.from_numpy(np.ascontiguousarray(scene[k]))
               for k in ("means", "quats", "scales", "opacities", "colors")}
    viewmat, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)

    def step() -> float:
        params = [t.clone().requires_grad_(True) for t in tensors.values()]
        rasterize(*params, viewmat, K, cam.width, cam.height, ctx=ctx).color.mean().backward()
        return float(params[0].grad.abs().sum())

    times: list[list[float]] = [[], []]
    sums = [0.0, 0.0]
    for r in range(rounds):
        for i in (0, 1) if r % 2 == 0 else (1, 0):
            ctx.shaders, ctx._pipelines = setups[i]
            step()   # the first step after a switch waits for the other side's buffers to settle
            for _ in range(2):
                start = time.perf_counter()
                sums[i] = step()
                if r >= 1:
                    times[i].append((time.perf_counter() - start) * 1e3)
    a, b = np.array(times[0]), np.array(times[1])
    print(f"public forward+backward: A {np.median(a):.1f} ms, B {np.median(b):.1f} ms, median of per-step "
          f"ratios B / A {np.median(b / a):.3f} ({a.size} steps each)")
    print(f"|d means| sums: A {sums[0]}, B {sums[1]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
