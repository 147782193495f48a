"""Why a render call after a pause is slower than the calls that follow it: GMA alone (no peer), the standard
scene's public forward+backward step (as ``peer_compare.py`` times it: the parameters' ``clone()``, the
render, the mean's backward) in bursts of three, each burst after a pause of one kind:

- ``none``: no pause (the burst follows the previous one);
- ``sleep``: the process sleeps, and the machine's cores idle;
- ``busy``: the process sleeps while one small spinning process per core keeps every core busy (little
  memory traffic), so that the cores never idle.

Prints, per kind, the medians of the bursts' first steps and of their later steps, whole and by phase.
``peer_compare.py``'s "after idle" column is such a first step (the peer had the cores for seconds
before it). The phases show where a first step's extra time goes: after idle cores most of it is in
the parameters' ``clone()`` (torch's first parallel op wakes its OpenMP worker), and with torch on one
thread (``OMP_NUM_THREADS=1``) a first step costs about what the later ones do, so the wait is torch's,
not GMA's.

    python benchmarks/first_call.py [--count 100000] [--pause 0.5] [--repeats 6]
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import load_standard_workload, machine, scene_tensors  # noqa: E402

from gma.core.args import positive_float, positive_int  # noqa: E402
from gma.gpu import get_context  # noqa: E402
from gma.render import rasterize  # noqa: E402

BURST = 3
KINDS = ("none", "sleep", "busy")
PHASES = ("clone", "forward", "loss", "backward")


def timed_step(scene: dict, ctx, size) -> list[float]:
    """One public forward+backward step as peer_compare.py's gma_step, the ms of each of PHASES."""
    marks = [time.perf_counter()]
    params = [scene[k].clone().requires_grad_(True) for k in ("means", "quats", "scales", "opacities", "colors")]
    marks.append(time.perf_counter())
    out = rasterize(*params, scene["viewmat"], scene["K"], *size, ctx=ctx)
    marks.append(time.perf_counter())
    loss = out.color.mean()
    marks.append(time.perf_counter())
    loss.backward()
    marks.append(time.perf_counter())
    return [(b - a) * 1e3 for a, b in zip(marks, marks[1:])]


def pause(kind: str, seconds: float) -> None:
    if kind == "sleep":
        time.sleep(seconds)
    elif kind == "busy":
        spinners = [subprocess.Popen(["sh", "-c", "while :; do :; done"]) for _ in range(os.cpu_count() or 1)]
        try:
            time.sleep(seconds)
        finally:
            for p in spinners:
                p.kill()
                p.wait()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=positive_int, default=100_000, help="surfels of the standard scene")
    ap.add_argument("--pause", type=positive_float, default=0.5, help="seconds of each pause")
    ap.add_argument("--repeats", type=positive_int, default=6, help="bursts per kind of pause")
    args = ap.parse_args(argv)
    workload = load_standard_workload()
    ctx = get_context()
    scene = scene_tensors(workload, args.count)
    size = (workload.WIDTH, workload.HEIGHT)
    print(f"adapter: {ctx.name}; machine: {machine()}; {args.count} surfels, pauses of {args.pause} s")
    for _ in range(BURST):   # compile the pipelines, size the buffers
        timed_step(scene, ctx, size)
    first: dict[str, list[list[float]]] = {k: [] for k in KINDS}
    later: dict[str, list[list[float]]] = {k: [] for k in KINDS}
    for _ in range(args.repeats):
        for kind in KINDS:   # interleaved, so that a drifting machine affects every kind alike
            pause(kind, args.pause)
            for i in range(BURST):
                (first if i == 0 else later)[kind].append(timed_step(scene, ctx, size))
    print("pause   step     ms  " + "  ".join(f"{p:>8s}" for p in PHASES))
    for kind in KINDS:
        for label, steps in (("first", first[kind]), ("later", later[kind])):
            whole = statistics.median(sum(s) for s in steps)
            phases = "  ".join(f"{statistics.median(s[j] for s in steps):8.1f}" for j in range(len(PHASES)))
            print(f"{kind:7s} {label:5s} {whole:7.1f}  {phases}")
    print(f"load after: {machine()}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
