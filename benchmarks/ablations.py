"""The paper's ablation table on one synthetic sequence: the full model against one-stage training, the
mesh layer only (coarse surfels) and direct binding (free per-surfel parameters on the body's own faces:
no features, decoders or mesh layer). Each variant is fitted with the same preset, seed and total number
of optimisation steps (S1 + S2), then evaluated on the held-out novel poses and views. Two-stage variants
run S1 coarse-layer steps then S2 steps of their final layer; one-stage training and direct binding
(which has no mesh layer for a geometry stage) run all S1 + S2 steps on the fine layer. Fits resume from
``--out`` (``--only`` refits or adds some variants and keeps the other rows of ``ablations.json``).

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
    from fit_helpers import fit_and_eval, sequence

    from gma.avatar import Avatar
    from gma.body import load_body
    from gma.gpu import get_context
    from gma.train.evaluate import geometry_metrics

    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seq", default="out/bench/seq", help="sequence (synthesised with --seed if missing)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--preset", default="quick")
    p.add_argument("--steps", type=int, nargs=2, default=None, metavar=("S1", "S2"),
                   help="override the preset's stage step counts")
    p.add_argument("--out", default="out/bench/ablations")
    p.add_argument("--only", type=int, nargs="+", default=None, metavar="I",
                   help="fit only these variants (0 full, 1 one-stage, 2 mesh only, 3 direct)")
    args = p.parse_args()
    ctx, body = get_context(), load_body("anny")
    seq = sequence(args.seq, args.seed)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    table = out / "ablations.json"
    rows = json.loads(table.read_text()) if args.only and table.is_file() else {}
    for i, (name, over) in enumerate(VARIANTS.items()):
        if args.only and i not in args.only:
            continue
        over = dict(over)
        if args.steps:
            over.update(stage1_steps=args.steps[0], stage2_steps=args.steps[1])
        print(f"== {name}")
        rows[name] = fit_and_eval(seq, out / f"v{i}.gma", args.preset, body, ctx, **over)
        rows[name]["overrides"] = over
        table.write_text(json.dumps({k: rows[k] for k in VARIANTS if k in rows}, indent=2))
    rows = {k: rows[k] for k in VARIANTS if k in rows}
    for i, name in enumerate(VARIANTS):  # rows kept from an earlier run may predate the column
        if name in rows and "geometry" not in rows[name] and (out / f"v{i}.gma").is_file():
            geometry = geometry_metrics(Avatar.load(out / f"v{i}.gma", body), seq)
            if geometry is not None:
                rows[name]["geometry"] = {k: round(v, 2) for k, v in geometry.items()}
    table.write_text(json.dumps(rows, indent=2))
    print(f"\nAblations ({args.preset} preset, {seq.root}); novel pose | novel view | mesh layer vs the "
          "ground-truth clothed mesh (mm, vertices the clothing moves; roughness = RMS Laplacian of the morph)")
    print(f"{'variant':32s} {'PSNR':>7s} {'SSIM':>7s} | {'PSNR':>7s} {'SSIM':>7s} | {'error':>6s} {'rough':>6s} | "
          f"{'steps':>5s} {'fit s':>6s} {'MB':>6s}")
    for name, r in rows.items():
        a, b = r["test_pose"], r["test_view"]
        g = r.get("geometry") or {}
        geo = f"{g['clothed_mm']:6.2f} {g['roughness_mm']:6.3f}" if g else f"{'-':>6s} {'-':>6s}"
        print(f"{name:32s} {a['psnr']:7.2f} {a['ssim']:7.4f} | {b['psnr']:7.2f} {b['ssim']:7.4f} | {geo} | "
              f"{r['steps']:5d} {r['fit_s']:6.0f} {r['avatar_mb']:6.2f}")
    if g:
        print(f"(unmorphed body: error {g['body_clothed_mm']:.2f} mm; ground-truth clothing roughness "
              f"{g['gt_roughness_mm']:.3f} mm)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
