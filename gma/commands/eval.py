"""``gma eval avatar.gma SEQ --split test``: PSNR / SSIM (/ LPIPS when its weights are installed) per
frame and mean, written as JSON and a table, with side-by-side images (target | render | error ×4)."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    p = subparsers.add_parser("eval", help="evaluate an avatar on a sequence split", description=__doc__)
    p.add_argument("avatar", help="fitted avatar (.gma)")
    p.add_argument("sequence", help="sequence directory")
    p.add_argument("--split", default="test",
                   help="split to evaluate (test, test_pose, test_view, train; 'test' falls back to "
                        "test_pose + test_view when the sequence has no 'test')")
    p.add_argument("--out", default=None, help="output folder (default: <avatar>.eval/)")
    p.add_argument("--resolution", type=int, default=512, help="longest image side to evaluate at")
    p.add_argument("--background", type=float, default=0.5, help="grey level behind the person")
    p.add_argument("--images", type=int, default=4, help="side-by-side images to write")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from gma.avatar import Avatar
    from gma.data import read_sequence
    from gma.train.evaluate import EVAL_SPLITS, evaluate_splits

    avatar = Avatar.load(args.avatar)
    seq = read_sequence(args.sequence)
    out = Path(args.out) if args.out else Path(args.avatar).with_suffix(".eval")
    splits = [args.split]
    if args.split == "test" and not seq.split("test"):
        splits = list(EVAL_SPLITS)
    results = evaluate_splits(avatar, seq, splits, out, args.resolution, args.background, images=args.images)
    geometry = results["geometry"]
    if geometry is not None:  # synthetic sequences carry the true clothed mesh
        print("mesh layer vs ground-truth clothed mesh: " + ", ".join(f"{k} {v:.2f}" for k, v in geometry.items()))
    print(f"wrote {out}")
    return 0
