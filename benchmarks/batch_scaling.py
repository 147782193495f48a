"""Wall time of ``gma batch`` for 1, 2 and 4 small synthetic people on this machine, and a paper estimate
of the throughput on N GPUs from the measured per-step and per-task costs.

    python benchmarks/batch_scaling.py [--people 1 2 4] [--size 64] [--steps 20 20] [--out out/bench/batch]

Each batch starts its own local Ray runtime (``num_cpus`` = the machine's cores, one core per person), fits
and evaluates every person (``--steps fit,eval``), and is timed from the call to the summary; the Ray
start-up is timed on its own. Expect no speed-up past the core count: with C cores, n people take about
ceil(n / C) times one person's time (more when other work shares the machine: the load is printed).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import time
from pathlib import Path

# The paper (AvatarBrush, Sec. 5): 40k steps (20k + 20k) take about 1.5 h on one RTX 4090, in ~12 GB.
PAPER_STEPS, PAPER_SECONDS, PAPER_GPU_GB = 40_000, 1.5 * 3600, 12


def _load() -> float:
    return os.getloadavg()[0]


def _people(root: Path, count: int, size: int):
    from gma.batch import find_people
    from gma.synth.generate import SynthConfig, synthesize

    for seed in range(1, count + 1):
        if not (root / f"p{seed}" / "splits.json").is_file():
            cfg = SynthConfig(width=size, height=size, train_frames=8, test_pose_frames=2, test_view_frames=2,
                              supersample=1, texture_size=256, seed=seed)
            synthesize(root / f"p{seed}", cfg, progress=False)
    return find_people([str(root / f"p{s}") for s in range(1, count + 1)])


def _ray_startup() -> float:
    import ray

    t0 = time.perf_counter()
    ray.init(num_cpus=os.cpu_count(), include_dashboard=False, log_to_driver=False)
    ray.shutdown()
    return time.perf_counter() - t0


def main() -> int:
    import shutil

    from gma.batch import BatchConfig
    from gma.batch.runner import run_batch
    from gma.batch.status import TaskStatus
    from gma.train.config import preset

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--people", type=int, nargs="+", default=[1, 2, 4])
    p.add_argument("--size", type=int, default=64, help="image size of the synthetic people")
    p.add_argument("--steps", type=int, nargs=2, default=[20, 20], help="fit steps of stage 1 and 2")
    p.add_argument("--out", default="out/bench/batch")
    args = p.parse_args()
    out = Path(args.out)
    people = _people(out / "people", max(args.people), args.size)
    fit = preset("quick", resolution=args.size, stage1_steps=args.steps[0], stage2_steps=args.steps[1],
                 preview_every=0, checkpoint_every=50)
    batch = BatchConfig(steps=("fit", "eval"), eval_resolution=args.size)
    cores = os.cpu_count()
    rows = {"machine": f"{cores} cores", "ray_startup_s": round(_ray_startup(), 1), "runs": []}
    for n in args.people:
        folder = out / f"run{n}"
        shutil.rmtree(folder, ignore_errors=True)
        load0, t0 = _load(), time.perf_counter()
        run_batch(people[:n], folder, batch, fit, progress=False, ray_init={"num_cpus": cores})
        wall = time.perf_counter() - t0
        tasks = [TaskStatus.read(folder / q.name) for q in people[:n]]
        metrics = [json.loads((folder / q.name / "avatar.fit" / "metrics.json").read_text()) for q in people[:n]]
        rows["runs"].append({
            "people": n, "wall_s": round(wall, 1), "load_before": round(load0, 2), "load_after": round(_load(), 2),
            "task_s": [t["seconds"] for t in tasks], "fit_s": [round(m["fit_seconds"], 1) for m in metrics],
            "ms_per_step": {k: round(sum(m["ms_per_step"][k] for m in metrics) / n, 1)
                            for k in metrics[0]["ms_per_step"]},
            "states": [t["state"] for t in tasks]})
        r = rows["runs"][-1]
        print(f"{n} people: {wall:.1f} s wall (load {r['load_before']} -> {r['load_after']}); per task "
              f"{r['task_s']} s, of which fit {r['fit_s']} s")
    one = rows["runs"][0]["wall_s"] / rows["runs"][0]["people"]
    print(f"\nRay start-up {rows['ray_startup_s']} s. Wall time against one person's ({one:.1f} s):")
    for r in rows["runs"]:
        ideal = math.ceil(r["people"] / cores)
        print(f"  {r['people']} people: x{r['wall_s'] / one:.2f} (no other load, {cores} cores: x{ideal}; "
              f"one after another: x{r['people']})")

    # Paper estimate: one fit per GPU (the paper's 12 GB fit uses a 4090's compute), Ray adds seconds.
    last = rows["runs"][-1]
    step_ms = sum(last["ms_per_step"].values())
    overhead = sum(t - f for t, f in zip(last["task_s"], last["fit_s"])) / len(last["task_s"])
    gpu_step_s = PAPER_SECONDS / PAPER_STEPS
    full_steps = preset("full").total_steps
    estimate = {"cpu_ms_per_step": round(step_ms, 1), "task_overhead_s": round(overhead, 1),
                "paper_gpu_ms_per_step": round(1000 * gpu_step_s, 1)}
    for name, steps in (("paper", PAPER_STEPS), ("gma_full", full_steps)):
        person_s = steps * gpu_step_s + overhead
        estimate[name] = {"steps": steps, "person_h": round(person_s / 3600, 2),
                          "people_per_day": {n: round(n * 86400 / person_s, 1) for n in (1, 2, 4, 8, 16, 64)}}
    rows["estimate"] = estimate
    split = ", ".join(f"{k} {v}" for k, v in last["ms_per_step"].items())
    print(f"\nPer step here: {step_ms:.0f} ms at {args.size} px ({split}); per task outside the fit (worker, body "
          f"model, GPU context, eval): {overhead:.1f} s")
    print(f"Paper: {PAPER_STEPS} steps in {PAPER_SECONDS / 3600:.1f} h on an RTX 4090 = "
          f"{estimate['paper_gpu_ms_per_step']} ms/step, one fit per GPU (--gpus-per-task 1; ~{PAPER_GPU_GB} GB each)")
    for name in ("paper", "gma_full"):
        e = estimate[name]
        print(f"  {name} ({e['steps']} steps, {e['person_h']} h per person), people per day on N GPUs: "
              + ", ".join(f"{n}: {v}" for n, v in e["people_per_day"].items()))
    out.mkdir(parents=True, exist_ok=True)
    (out / "scaling.json").write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
