"""Helpers of the fit benchmarks (fit_presets.py, ablations.py, shared_decoders.py): get (or synthesise) a
sequence, fit one variant, evaluate it with the same loop as ``gma eval``."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from gma.data import read_sequence
from gma.synth.generate import SynthConfig, synthesize
from gma.train.config import preset
from gma.train.evaluate import EVAL_SPLITS, evaluate_splits
from gma.train.trainer import Trainer, work_dir

# GMA_BENCH_SMOKE=1 (tests/test_benchmarks.py) runs every fit benchmark end to end in seconds, on tiny
# people and a few steps, so that no script rots; its figures mean nothing.
SMOKE = os.environ.get("GMA_BENCH_SMOKE") == "1"
SMOKE_OVERRIDES = dict(resolution=48, stage1_steps=1, stage2_steps=1, checkpoint_every=1, log_every=1,
                       preview_every=0, avatar={"feature_dim": 8, "fine_per_face": 1})


def smoke_overrides(**overrides) -> dict:
    """``overrides`` on top of the ones that make a fit tiny in smoke mode (nested dicts merged)."""
    out = {k: dict(v) if isinstance(v, dict) else v for k, v in (SMOKE_OVERRIDES if SMOKE else {}).items()}
    for k, v in overrides.items():
        out[k] = {**out.get(k, {}), **v} if isinstance(v, dict) else v
    return out


def sequence(path: str, seed: int = 0, size: int = 512):
    p = Path(path)
    if (p / "splits.json").is_file():
        return read_sequence(p)
    if SMOKE:
        return synthesize(p, SynthConfig(seed=seed, width=48, height=48, train_frames=2, test_pose_frames=1,
                                         test_view_frames=1, supersample=1, texture_size=128), progress=False)
    return synthesize(p, SynthConfig(seed=seed, width=size, height=size))


def fit_and_eval(seq, out: Path, preset_name: str, body, ctx, eval_resolution: int | None = None,
                 **overrides) -> dict:
    """Fit ``preset_name`` with ``overrides`` into ``out``, evaluate test_pose and test_view; a dict row."""
    cfg = preset(preset_name, **smoke_overrides(**overrides))
    t0 = time.perf_counter()
    avatar = Trainer(cfg, seq, out, body=body, ctx=ctx).run(resume=True)
    fit_s = time.perf_counter() - t0
    metrics = json.loads((work_dir(out) / "metrics.json").read_text())
    row = {"fit_s": round(metrics["fit_seconds"], 1), "wall_s": round(fit_s, 1), "steps": metrics["steps"],
           "avatar_mb": round(out.stat().st_size / 2**20, 2),
           "ms_per_step": {k: round(v, 1) for k, v in metrics["ms_per_step"].items()}}
    row.update(evaluate_row(avatar, seq, out.with_suffix(".eval"), eval_resolution or cfg.resolution,
                            cfg.background, body, ctx))
    return row


def evaluate_row(avatar, seq, eval_dir: Path, resolution: int, background: float, body, ctx) -> dict:
    """Mean metrics of ``avatar`` on test_pose and test_view (images in ``eval_dir``), and the geometry
    scores when ``seq`` has a ground-truth mesh: {"test_pose": {...}, "test_view": {...}[, "geometry"]}."""
    results = evaluate_splits(avatar, seq, EVAL_SPLITS, eval_dir, resolution, background, body=body, ctx=ctx,
                              report=None)
    row = {split: {k: round(v, 4) for k, v in r["mean"].items()} for split, r in results.items() if split != "geometry"}
    if results["geometry"] is not None:
        row["geometry"] = {k: round(v, 2) for k, v in results["geometry"].items()}
    return row
