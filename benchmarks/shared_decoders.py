"""Shared decoders, as in the paper: train the decoders over several synthetic people, then fit a new
person's features only against them (frozen), and compare with that person fitted on its own.

    python benchmarks/shared_decoders.py [--seq out/bench/seq] [--train-seeds 1 2] [--preset quick]

Prints novel-pose / novel-view PSNR and SSIM of: each training person (from the shared fit), the new
person with frozen shared decoders, and the new person with its own decoders; plus fit times. The
shared fit runs the preset's steps once per training person, so each person sees as many steps as a
single fit. Fits resume from ``--out``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def main() -> int:
    from fit_helpers import evaluate_row, fit_and_eval, sequence, smoke_overrides

    from gma.avatar import Avatar
    from gma.body import load_body
    from gma.gpu import get_context
    from gma.train.config import preset
    from gma.train.trainer import Trainer, work_dir

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seq", default="out/bench/seq", help="the new person (synthesised with seed 0 if missing)")
    p.add_argument("--train-seeds", type=int, nargs="+", default=[1, 2], help="synthetic people for the decoders")
    p.add_argument("--preset", default="quick")
    p.add_argument("--training", default="two_stage", choices=("two_stage", "one_stage"),
                   help="training of every fit here (one_stage: the paper's ablation, whose colour decoder it "
                        "says generalises worse to new people)")
    p.add_argument("--out", default="out/bench/shared")
    args = p.parse_args()
    ctx, body = get_context(), load_body("anny")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows: dict[str, dict] = {}

    train_seqs = [sequence(str(out / f"seq{s}"), s) for s in args.train_seeds]
    base = preset(args.preset, **smoke_overrides())
    n = len(train_seqs)
    cfg = preset(args.preset, **smoke_overrides(stage1_steps=base.stage1_steps * n,
                                                stage2_steps=base.stage2_steps * n, training=args.training))
    t0 = time.perf_counter()
    trainer = Trainer(cfg, train_seqs, out / "decoders", body=body, ctx=ctx)
    trainer.run(resume=True)
    shared_s = json.loads((work_dir(out / "decoders") / "metrics.json").read_text())["fit_seconds"]
    print(f"shared decoders over {n} people: {shared_s:.0f} s ({time.perf_counter() - t0:.0f} s wall)")
    for sub in trainer.subjects:
        row = evaluate_row(Avatar.load(sub.out, body), sub.seq, sub.out.with_suffix(".eval"), cfg.resolution,
                           cfg.background, body, ctx)
        rows[f"training person {sub.name} (shared fit)"] = {"fit_s": round(shared_s / n, 1), **row}

    seq = sequence(args.seq, 0)
    decoders = str(out / "decoders" / "decoders.gma")
    rows["new person, frozen shared decoders"] = fit_and_eval(seq, out / "new_frozen.gma", args.preset, body, ctx,
                                                              decoders=decoders, training=args.training)
    rows["new person, own decoders"] = fit_and_eval(seq, out / "new_own.gma", args.preset, body, ctx,
                                                    training=args.training)
    (out / "shared.json").write_text(json.dumps(rows, indent=2))

    print(f"\nShared decoders ({args.preset} preset, {args.training}); novel pose | novel view")
    print(f"{'avatar':40s} {'PSNR':>7s} {'SSIM':>7s} | {'PSNR':>7s} {'SSIM':>7s} | {'fit s':>6s}")
    for name, r in rows.items():
        a, b = r["test_pose"], r["test_view"]
        print(f"{name:40s} {a['psnr']:7.2f} {a['ssim']:7.4f} | {b['psnr']:7.2f} {b['ssim']:7.4f} | {r['fit_s']:6.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
