"""The paper's ablation table on one synthetic sequence: the full model against one-stage training, the
mesh layer only (coarse surfels) and direct binding (free per-surfel parameters, no features/decoders).
Each variant is fitted with the same preset, seed and step counts, then evaluated on the held-out novel
poses and views.

    python benchmarks/ablations.py [--seq out/bench/seq] [--preset quick] [--out out/bench/ablations]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

VARIANTS = {
    "full (two-stage, 3 layers)": {},
    "one-stage training": {"training": "one_stage"},
    "mesh layer only (coarse)": {"avatar": {"representation": "mesh_only"}},
    "direct binding (no decoders)": {"avatar": {"representation": "direct"}},
}


def main() -> int:
    from gma.body import load_body
    from gma.gpu import get_context
    from gma.train.bench_helpers import fit_and_eval, sequence

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seq", default="out/bench/seq", help="sequence (synthesised with --seed if missing)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--preset", default="quick")
    p.add_argument("--steps", type=int, nargs=2, default=None, metavar=("S1", "S2"),
                   help="override the preset's stage step counts")
    p.add_argument("--out", default="out/bench/ablations")
    args = p.parse_args()
    ctx, body = get_context(), load_body("anny")
    seq = sequence(args.seq, args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    rows = {}
    for i, (name, over) in enumerate(VARIANTS.items()):
        over = dict(over)
        if args.steps:
            over.update(stage1_steps=args.steps[0], stage2_steps=args.steps[1])
        print(f"== {name}")
        rows[name] = fit_and_eval(seq, out / f"v{i}.gma", args.preset, body, ctx, **over)
    (out / "ablations.json").write_text(json.dumps(rows, indent=2))
    print(f"\nAblations ({args.preset} preset, {seq.root}); novel pose | novel view")
    print(f"{'variant':32s} {'PSNR':>7s} {'SSIM':>7s} | {'PSNR':>7s} {'SSIM':>7s} | {'fit s':>6s} {'MB':>6s}")
    for name, r in rows.items():
        a, b = r["test_pose"], r["test_view"]
        print(f"{name:32s} {a['psnr']:7.2f} {a['ssim']:7.4f} | {b['psnr']:7.2f} {b['ssim']:7.4f} | "
              f"{r['fit_s']:6.0f} {r['avatar_mb']:6.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
