"""Helpers of the fit benchmarks (fit_presets.py, ablations.py, shared_decoders.py): get (or synthesise) a
sequence, fit one variant, evaluate it with the same loop as ``gma eval``."""

from __future__ import annotations

import json
import time
from pathlib import Path

from gma.data import read_sequence
from gma.synth.generate import SynthConfig, synthesize
from gma.train.config import preset
from gma.train.evaluate import EVAL_SPLITS, evaluate_splits
from gma.train.trainer import Trainer, work_dir


def sequence(path: str, seed: int = 0, size: int = 512):
    p = Path(path)
    if (p / "splits.json").is_file():
        return read_sequence(p)
    return synthesize(p, SynthConfig(seed=seed, width=size, height=size))


def fit_and_eval(seq, out: Path, preset_name: str, body, ctx, eval_resolution: int | None = None,
                 **overrides) -> dict:
    """Fit ``preset_name`` with ``overrides`` into ``out``, evaluate test_pose and test_view; a dict row."""
    cfg = preset(preset_name, **overrides)
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
