#!/usr/bin/env python3
"""The GPU sort's variants against each other in one process, on the renderer's two kinds of keys: depth
keys (``--depth-bits`` bits above a base, as projection's min/max trim them) and tile keys (``--tile-bits``
bits of tile id with an intersection's number above them, unsorted, as a replayed render emits them).
Each round times ``--repeat`` sorts in one submission per variant, alternating the order; prints the
medians and the median of the per-round ratios to the 4-bit radix sort. The lane-ordered variant runs
where ``lane_sort_supported`` (lavapipe, 8-lane subgroups); both must equal numpy's stable argsort.

    python benchmarks/sort.py [--depth-keys 100000] [--tile-keys 224000] [--rounds 20]
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
from common import machine  # noqa: E402

from gma.gpu import get_context  # noqa: E402
from gma.render.gpu_sort import SORT_BLOCK, RadixSorter, dispatch_info, lane_sort_supported  # noqa: E402

INDIRECT = wgpu.BufferUsage.STORAGE | wgpu.BufferUsage.INDIRECT | wgpu.BufferUsage.COPY_DST


def key_sets(args) -> list[tuple[str, np.ndarray, int, int | None]]:
    """(name, keys, bits, base) of the renderer's depth and tile sorts."""
    rng = np.random.default_rng(0)
    base = (1 << 22) - 5000   # crosses a power of two, as depth keys may
    depth = (base + rng.integers(0, 1 << args.depth_bits, args.depth_keys)).astype(np.uint32)
    tiles = rng.integers(0, 1 << args.tile_bits, args.tile_keys) | (rng.integers(0, 40, args.tile_keys) << 16)
    return [(f"depth {args.depth_keys} x {args.depth_bits} bits", depth, args.depth_bits, base),
            (f"tiles {args.tile_keys} x {args.tile_bits} bits", tiles.astype(np.uint32), args.tile_bits, None)]


def check(sorter: RadixSorter, keys: np.ndarray, bits: int, base: int | None) -> None:
    _, order = sorter.sort(keys, bits=bits, base=base)
    digits = (keys - np.uint32(base or 0)) & np.uint32((1 << bits) - 1)   # wraps, as the sort's
    if not np.array_equal(order, np.argsort(digits, kind="stable")):
        raise SystemExit(f"the {'lane-ordered' if sorter.lanes else '4-bit'} sort is wrong: not a stable sort")


def time_rounds(ctx, sorters: dict[str, RadixSorter], keys: np.ndarray, bits: int, base: int | None,
                rounds: int, repeat: int) -> dict[str, list[float]]:
    """Per variant, per round: ms per sort (``repeat`` sorts in one submission, read back as the fence)."""
    n = keys.size
    kb, vb = ctx.upload(keys, "keys"), ctx.upload(np.arange(n, dtype=np.uint32), "values")
    info = ctx.upload(dispatch_info(n, SORT_BLOCK), "sort.info", INDIRECT)
    based = (ctx.upload(np.array([base], np.uint32), "sort.base"), 0) if base is not None else None
    times: dict[str, list[float]] = {name: [] for name in sorters}
    names = list(sorters)
    for r in range(rounds + 1):
        for name in names if r % 2 == 0 else names[::-1]:
            enc = ctx.device.create_command_encoder()
            for _ in range(repeat):
                sorters[name].encode(enc, info, kb, vb, n, bits, base=based)
            t0 = time.perf_counter()
            ctx.submit(enc)
            ctx.read(vb, np.uint32, 1)
            if r:  # round 0 compiles the pipelines
                times[name].append((time.perf_counter() - t0) * 1e3 / repeat)
    return times


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--depth-keys", type=int, default=100_000)
    p.add_argument("--depth-bits", type=int, default=18, help="the standard scene's depth sort: 18")
    p.add_argument("--tile-keys", type=int, default=224_000)
    p.add_argument("--tile-bits", type=int, default=10, help="1024 tiles (512x512): 10")
    p.add_argument("--rounds", type=int, default=20)
    p.add_argument("--repeat", type=int, default=4, help="sorts per timed submission")
    args = p.parse_args()
    for name in ("depth_keys", "tile_keys", "rounds", "repeat"):
        if getattr(args, name) < 1:
            print(f"--{name.replace('_', '-')} must be at least 1", file=sys.stderr)
            return 2
    for name, most in (("depth_bits", 32), ("tile_bits", 16)):   # tile ids lie below the record numbers
        if not 1 <= getattr(args, name) <= most:
            print(f"--{name.replace('_', '-')} must lie in 1..{most}", file=sys.stderr)
            return 2
    ctx = get_context()
    sorters = {"4-bit radix": RadixSorter(ctx, lanes=False)}
    if lane_sort_supported(ctx):
        sorters["lane-ordered"] = RadixSorter(ctx, lanes=True)
    print(f"adapter: {ctx.name}; {machine()}")
    if len(sorters) == 1:
        print("the lane-ordered sort runs on lavapipe with 8-lane subgroups only: timing the 4-bit sort alone")
    print(f"{'keys':28s} {'variant':14s} {'passes':>6s} {'ms':>8s} {'ratio':>7s}  (median of per-round ratios)")
    for label, keys, bits, base in key_sets(args):
        for sorter in sorters.values():
            check(sorter, keys, bits, base)
        times = time_rounds(ctx, sorters, keys, bits, base, args.rounds, args.repeat)
        reference = times["4-bit radix"]
        for name, sorter in sorters.items():
            ratio = statistics.median(t / ref for t, ref in zip(times[name], reference))
            print(f"{label:28s} {name:14s} {sorter.passes(bits):6d} {statistics.median(times[name]):8.2f} "
                  f"{ratio:7.3f}")
    print(f"load after: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
