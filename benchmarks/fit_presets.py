"""Fit the default synthetic sequence with the quick and/or full preset and print novel-pose and
novel-view PSNR/SSIM, fit time, avatar size and the per-step time split.

    python benchmarks/fit_presets.py [--presets quick full] [--seq out/bench/seq]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path


def main() -> int:
    from fit_helpers import fit_and_eval, sequence

    from gma.body import load_body
    from gma.gpu import get_context

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--presets", nargs="+", default=["quick"])
    p.add_argument("--seq", default="out/bench/seq")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="out/bench/presets")
    args = p.parse_args()
    ctx, body = get_context(), load_body("anny")
    print(f"adapter: {ctx.name}")
    seq = sequence(args.seq, args.seed)
    rows = {name: fit_and_eval(seq, Path(args.out) / f"{name}.gma", name, body, ctx) for name in args.presets}
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "presets.json").write_text(json.dumps(rows, indent=2))
    for name, r in rows.items():
        a, b = r["test_pose"], r["test_view"]
        print(f"{name}: novel pose PSNR {a['psnr']:.2f} SSIM {a['ssim']:.4f}; novel view PSNR {b['psnr']:.2f} "
              f"SSIM {b['ssim']:.4f}; fit {r['fit_s']:.0f} s ({r['steps']} steps); {r['avatar_mb']} MB")
        print("   ms/step: " + ", ".join(f"{k} {v}" for k, v in r["ms_per_step"].items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
