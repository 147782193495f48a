"""``gma demo``: the whole method on the built-in default, end to end — synthesise the default sequence
(a clothed Anny person turning), fit an avatar (two stages), evaluate it on held-out novel poses and
views, write a turntable video and a novel-pose animation video, then edit it as the method is meant to
be used (a painted sleeve, a logo on the chest, mirrored cuffs, a second person's trousers fitted against
the same decoders; see gma/commands/_demo_edit.py) and write ``edited_turntable.mp4`` and a short summary.

``--quick`` (default) finishes within minutes on a small CPU with lavapipe; ``--full`` is the
GPU setting. Re-running continues where a killed run stopped (the sequence is reused, the fit resumes)."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="synthesise, fit, evaluate and animate an avatar", description=__doc__)
    p.add_argument("--out", default="out/demo", help="output folder")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--quick", dest="preset", action="store_const", const="quick", help="CPU preset (default)")
    g.add_argument("--full", dest="preset", action="store_const", const="full", help="GPU preset")
    p.add_argument("--seed", type=int, default=0, help="synthetic person and fit seed")
    p.add_argument("--video-size", type=int, default=0, help="video frame size (default: 256 quick, 512 full)")
    p.add_argument("--motion", default="walk", help="built-in motion for the novel-pose video (walk, wave, ...)")
    p.set_defaults(func=run, preset="quick")


def format_metric(name: str, value: float) -> str:
    """One metric as the summary prints it: every PSNR in dB with two decimals, other scores with four."""
    return f"{name} {value:.2f} dB" if name.startswith("psnr") else f"{name} {value:.4f}"


def run(args: argparse.Namespace) -> int:
    from gma.body import load_body
    from gma.commands._demo_edit import edit_stage
    from gma.commands._openmp_workers import openmp_workers_asleep
    from gma.edit.unseen import AfterFit
    from gma.gpu import get_context
    from gma.render.api import around_device_work
    from gma.train.config import preset
    from gma.train.evaluate import EVAL_SPLITS, evaluate_splits
    from gma.train.trainer import Trainer

    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    t_all = time.perf_counter()
    times: dict[str, float] = {}
    ctx = get_context()
    body = load_body("anny")
    print(f"[demo] adapter: {ctx.name}; preset {args.preset}")

    t0 = time.perf_counter()
    seq = _sequence(out / "sequence", args.seed, body, ctx)
    times["synth_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    cfg = preset(args.preset, seed=args.seed)
    avatar_path = out / "avatar.gma"
    trainer = Trainer(cfg, seq, avatar_path, body=body, ctx=ctx, finish=AfterFit(ctx))
    with around_device_work(openmp_workers_asleep):   # (as gma fit: see _openmp_workers.py)
        avatar = trainer.run(resume=True)
    times["fit_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    evaluated = evaluate_splits(avatar, seq, EVAL_SPLITS, out / "eval", cfg.resolution, cfg.background,
                                body=body, ctx=ctx)
    results = {split: r["mean"] for split, r in evaluated.items() if split != "geometry"}
    times["eval_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    size = args.video_size or (256 if args.preset == "quick" else 512)
    videos = _videos(out, avatar, seq, body, ctx, size, cfg.background, args.motion)
    times["video_s"] = time.perf_counter() - t0

    editing = edit_stage(out, avatar_path, args.preset, args.seed, body, ctx, videos["camera"], cfg.background,
                         size)
    times.update(editing["times_s"])
    times["total_s"] = time.perf_counter() - t_all
    _write_summary(out, args, ctx, avatar_path, videos, results, editing, times)
    return 0


def _sequence(seq_dir: Path, seed: int, body, ctx):
    """The default synthetic sequence: reused when a previous run wrote it whole, else synthesised."""
    from gma.data import read_sequence
    from gma.synth.generate import SynthConfig, synthesize

    if (seq_dir / "splits.json").is_file():
        print(f"[demo] reusing {seq_dir}")
        return read_sequence(seq_dir)
    seq = synthesize(seq_dir, SynthConfig(seed=seed), ctx=ctx, body=body)
    print(f"[demo] synthesised {seq_dir}: {len(seq)} frames at {seq.width}x{seq.height}")
    return seq


def _videos(out: Path, avatar, seq, body, ctx, size: int, background: float, motion_name: str) -> dict:
    """The turntable, the novel-pose animation and a novel-pose still: their paths, the sequence camera
    (K, w2c) at ``size`` and the number of surfels drawn."""
    from gma.avatar.gpu import AvatarRenderer
    from gma.avatar.posing import frame_params
    from gma.avatar.video import orbit_cameras, render_turntable, sequence_camera, write_video
    from gma.body import motion
    from gma.render.image_io import save_png

    renderer = AvatarRenderer(ctx, avatar, body)
    K, w2c = sequence_camera(seq, size)
    bg = (background,) * 3
    canon = body.canonical_params(avatar.shape)
    turntable = write_video(out / "turntable.mp4", render_turntable(renderer, canon, K, w2c, size, 72, bg))
    mot = motion(motion_name, frames=72, body=body, shape=avatar.shape)
    cam = orbit_cameras(w2c, K, size, size, 1)[0]
    anim = [renderer.render(mot.params(i), cam, bg) for i in range(len(mot))]
    animation = write_video(out / f"novel_pose_{motion_name}.mp4", anim)
    # A test_pose frame as a still, for the summary.
    frame = seq.split("test_pose")[0] if seq.split("test_pose") else seq.split("train")[0]
    still = renderer.render(frame_params(seq.body.model, seq.body.frame(frame)), cam, bg)
    save_png(out / "novel_pose_still.png", still)
    return {"turntable": turntable, "animation": animation, "camera": (K, w2c),
            "surfels": len(renderer.decoded.binding)}


def _write_summary(out: Path, args, ctx, avatar_path: Path, videos: dict, results: dict, editing: dict,
                   times: dict) -> None:
    """summary.json (everything) and summary.txt (what to read first), also printed."""
    from gma.core.atomic import atomic_write_bytes, atomic_write_json
    from gma.train.trainer import work_dir

    fit_metrics = json.loads((work_dir(avatar_path) / "metrics.json").read_text())
    turntable, animation = videos["turntable"], videos["animation"]
    summary = {"preset": args.preset, "adapter": ctx.name, "sequence": str(out / "sequence"),
               "avatar": str(avatar_path),
               "avatar_mb": round(avatar_path.stat().st_size / 2**20, 2), "surfels": videos["surfels"],
               "fit_steps": fit_metrics["steps"], "fit_resolution": fit_metrics["resolution"],
               "ms_per_step": {k: round(v, 1) for k, v in fit_metrics["ms_per_step"].items()},
               "metrics": results, "times_s": {k: round(v, 1) for k, v in times.items()},
               "videos": [str(turntable), str(animation)], "edits": editing["edits"],
               "edit_files": editing["files"]}
    atomic_write_json(out / "summary.json", summary)
    lines = [f"GMA demo ({args.preset} preset) on {ctx.name}",
             f"avatar {avatar_path} ({summary['avatar_mb']} MB, {summary['surfels']} surfels), "
             f"fit {fit_metrics['steps']} steps at {fit_metrics['resolution'][1]} px in {times['fit_s']:.0f} s"]
    for split, m in results.items():
        lines.append(f"{split:10s} " + "  ".join(format_metric(k, v) for k, v in m.items()))
    for e in editing["edits"]:
        lines.append(f"edit: {e['edit']}: {e['faces']} faces in {e['seconds']:.2f} s")
    lines.append(f"edited avatar {editing['files'][0]} (second person fitted against the same decoders in "
                 f"{times['donor_fit_s']:.0f} s); pictures in {out / 'edits'}")
    lines.append(f"videos: {turntable}, {animation}, {editing['files'][1]}; total {times['total_s']:.0f} s")
    atomic_write_bytes(out / "summary.txt", ("\n".join(lines) + "\n").encode())
    print("\n".join(lines))
