"""The side the camera never saw: a synthetic person turning once in front of a fixed camera, fitted on
only part of the turn, scored on the views the fit never had, before and after the fill of the unseen
faces (``gma.edit.unseen``, what ``gma fit`` runs after the fit).

Two cases, one fit each (the fill is a step after the fit, so "before" and "after" are the same fit):

- ``front``: training frames within +-60 deg of facing the camera (a phone propped up in front of
  someone); scored on the back (150-210 deg) and on the sides (75-105 and 255-285 deg).
- ``left-right``: a turn that stops short, training frames from -30 to 210 deg (front, left side, back);
  scored on the other side (250-290 deg), which the symmetry prior (on in both) covers.

Scores per view set: PSNR over the image, and the mean absolute colour error (0-255) inside the true
silhouette, before the fill and after it with each weight of its front-to-back prior (``--front-back``:
``default``, the fill's per-group weights, or one weight for every group), with and without the crown
prior of the head (``--no-crown``, one more fill with the first weight).
Writes a table (stdout and ``--work``/results.json) and ``--figure``: a back view, ground truth | before |
after (the first weight). A fit already finished in ``--work`` is reused.

    python benchmarks/unseen_sides.py --size 160 --frames 36 --steps 120 240
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

from gma.avatar import Avatar  # noqa: E402
from gma.body import load_body  # noqa: E402
from gma.data import read_sequence  # noqa: E402
from gma.edit.unseen import AfterFit  # noqa: E402
from gma.gpu import get_context  # noqa: E402
from gma.render.image_io import save_png  # noqa: E402
from gma.synth.generate import SynthConfig, synthesize  # noqa: E402
from gma.train.config import preset  # noqa: E402
from gma.train.data import load_frames  # noqa: E402
from gma.train.metrics import psnr  # noqa: E402
from gma.train.render_step import render_frame  # noqa: E402
from gma.train.trainer import Trainer  # noqa: E402

# Case -> (training angles, {view set: scored angles}), in degrees of the person's turn (0: facing the camera).
CASES = {
    "front": ([(-60, 60)], {"back": [(150, 210)], "sides": [(75, 105), (255, 285)]}),
    "left-right": ([(-30, 210)], {"other side": [(250, 290)]}),
}


def _frames_within(n: int, ranges) -> list[int]:
    """Frames of an n-frame turn (frame t at 360 t / n deg) whose angle lies in one of ``ranges``."""
    out = []
    for t in range(n):
        a = 360.0 * t / n
        if any(lo <= a <= hi or lo <= a - 360 <= hi for lo, hi in ranges):
            out.append(t)
    return out


def _sequence(work: Path, size: int, frames: int, body, ctx):
    path = work / "person"
    if (path / "splits.json").is_file():
        return read_sequence(path)
    cfg = SynthConfig(seed=0, width=size, height=size, train_frames=frames, test_pose_frames=0,
                      test_view_frames=0, supersample=2, texture_size=1024)
    return synthesize(path, cfg, ctx=ctx, body=body, progress=False)


def _case_sequence(work: Path, base, case: str):
    """A copy of the sequence's splits for one case (images are linked, not copied)."""
    train, views = CASES[case]
    n = len(base.split("train"))
    out = work / case.replace(" ", "_")
    out.mkdir(parents=True, exist_ok=True)
    for name in ("images", "masks", "cameras.json", "body.npz"):
        link = out / name
        if not link.exists():
            link.symlink_to((Path(base.root) / name).resolve())
    splits = {"train": _frames_within(n, train)}
    splits.update({v: _frames_within(n, r) for v, r in views.items()})
    (out / "splits.json").write_text(json.dumps(splits))
    return read_sequence(out)


@torch.no_grad()
def score_views(avatar, seq, split: str, resolution: int, body, ctx) -> tuple[dict, list[np.ndarray]]:
    """({psnr, colour_error, frames}, [ground truth | render] per frame) of ``avatar`` on a split of
    ``seq`` at ``resolution``: PSNR over the image, colour error (0-255) inside the true silhouette."""
    frames = load_frames(seq, body, split, resolution, identity=avatar.shape)
    decoded = avatar.decode()
    psnrs, errors, images = [], [], []
    for t in range(len(frames)):
        out, _ = render_frame(decoded, body, frames, t, 0.5, ctx, cull=False)
        target = frames.target(t, 0.5)
        inside = frames.masks[t, ..., 0] > 0.5
        psnrs.append(psnr(out.color, target))
        errors.append(float(255 * (out.color - target).abs()[inside].mean()))
        images.append(np.concatenate([target.numpy(), out.color.clamp(0, 1).numpy()], 1))
    return {"psnr": round(float(np.mean(psnrs)), 2), "colour_error": round(float(np.mean(errors)), 2),
            "frames": len(frames)}, images


def _weights(name: str):
    """``--front-back`` value -> ``AfterFit``'s front_back (None: the fill's default per-group weights)."""
    return None if name == "default" else float(name)


def run_case(case: str, seq, work: Path, args, body, ctx) -> dict:
    """Fit (or reuse a finished fit in ``work``), score before the fill and after it with each
    ``--front-back`` weight (a fresh copy of the fitted avatar each)."""
    cfg = preset("quick", resolution=args.size, stage1_steps=args.steps[0], stage2_steps=args.steps[1],
                 preview_every=0)
    out = work / f"{case.replace(' ', '_')}.gma"
    t0 = time.perf_counter()
    trainer = Trainer(cfg, seq, out, body=body, ctx=ctx, progress=False)
    avatar = trainer.run(resume=True)  # Trainer without a finish step: the avatar as the fit left it
    fit_s = time.perf_counter() - t0
    views = list(CASES[case][1])
    before = {v: score_views(avatar, seq, v, args.size, body, ctx) for v in views}
    meshes = list(trainer.posed_meshes(0))
    result = {"train_frames": len(seq.split("train")), "fit_s": round(fit_s, 1), "fills": {}}
    variants = [(w, True) for w in args.front_back] + ([(args.front_back[0], False)] if args.no_crown else [])
    for k, (weight, crown) in enumerate(variants):
        filled = Avatar.load(out, body)
        t0 = time.perf_counter()
        fill = AfterFit(ctx, front_back=_weights(weight), crown=crown)
        summary = fill(filled, body, iter(meshes), mirror=cfg.symmetry > 0)
        after = {v: score_views(filled, seq, v, args.size, body, ctx) for v in views}
        name = weight + ("" if crown else ", no crown")
        result["fills"][name] = {"fill_s": round(time.perf_counter() - t0, 1), "guessed": summary["guessed"],
                                   "filled": summary["filled"], "views": {v: after[v][0] for v in views}}
        if case == "front" and k == 0:
            mid = len(before["back"][1]) // 2  # the frame nearest 180 deg
            w = after["back"][1][mid].shape[1] // 2
            result["figure"] = np.concatenate([before["back"][1][mid], after["back"][1][mid][:, w:]], 1)
    result["before"] = {v: before[v][0] for v in views}
    return result


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="out/bench_unseen", help="folder for the sequence, fits and results")
    ap.add_argument("--figure", default="docs/unseen_back.png", help="back view: ground truth | before | after")
    ap.add_argument("--size", type=int, default=192, help="image size of the sequence and the fit (pixels)")
    ap.add_argument("--frames", type=int, default=36, help="frames in the whole turn (every 360/N deg)")
    ap.add_argument("--steps", type=int, nargs=2, default=(200, 400), help="stage 1 and stage 2 steps")
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=list(CASES))
    ap.add_argument("--front-back", nargs="+", default=("default", "0", "0.5", "1"),
                    help="front-to-back weights to score: 'default' (the fill's per-group weights) or one weight "
                         "for every group (the first: the figure)")
    ap.add_argument("--no-crown", action="store_true", help="also fill with the first weight without the crown prior")
    args = ap.parse_args(argv)
    if args.size < 16 or args.frames < 6 or min(args.steps) < 1:
        ap.error("need --size >= 16, --frames >= 6 and at least one step per stage")
    try:
        if not all(w == "default" or 0 <= float(w) <= 1 for w in args.front_back):
            raise ValueError
    except ValueError:
        ap.error("--front-back: 'default' or weights in [0, 1]")
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    ctx, body = get_context(), load_body("anny")
    base = _sequence(work, args.size, args.frames, body, ctx)
    results = {}
    for case in args.cases:
        results[case] = run_case(case, _case_sequence(work, base, case), work, args, body, ctx)
        figure = results[case].pop("figure", None)
        if figure is not None:
            save_png(Path(args.figure), figure)
    print(f"# unseen sides: {machine()}; {args.frames}-frame turn at {args.size} px, quick preset, steps "
          f"{args.steps[0]}+{args.steps[1]}")
    print("| case | views (frames) | train frames | front-back weight | PSNR before | after | colour error before "
          "| after | guessed area |")
    print("|---|---|---|---|---|---|---|---|---|")
    for case, r in results.items():
        for view, b in r["before"].items():
            for weight, filled in r["fills"].items():
                a = filled["views"][view]
                print(f"| {case} | {view} ({b['frames']}) | {r['train_frames']} | {weight} | {b['psnr']:.2f} | "
                      f"{a['psnr']:.2f} | {b['colour_error']:.1f} | {a['colour_error']:.1f} | "
                      f"{100 * filled['guessed']['area']:.0f} % |")
    (work / "results.json").write_text(json.dumps({"args": vars(args), "machine": machine(), "results": results},
                                                  indent=1, default=str))
    return 0


if __name__ == "__main__":
    sys.exit(main())
