"""The whole real path, against ground truth (issue 12): a ``gma synth`` turn rendered to an mp4 (no
masks, no poses), ``gma import video`` on it, quick fits with and without pose refinement, and the same
fit on the true poses; each avatar scored on the synthetic sequence's held-out novel poses (true poses
on the avatar's own body shape — the one it was fitted on —, true images), before and after test-time
pose fitting. The gap between the true-pose and the
estimated-pose avatar is the price of pose estimation and of the video itself; a fourth fit, the true
poses on the imported sequence's own frames and masks, splits the two.

Then the real iPER clip (``common.iper_clip()``, last quarter held out): bounding-box PSNR of the
held-out frames without refinement, with refinement in the fit, and with test-time pose fitting too, and
a before/after picture (``--figure``, default docs/iper_pose_refinement.png), and the refined fit without
the left-right symmetry prior beside it (docs/iper_symmetry.png). The clip is one turn, so
its last quarter shows views no training frame shows; ``--interleaved`` also holds out every fourth
frame instead (views between training views) and prints the same rows for that split.

    python benchmarks/video_to_avatar.py [--work /tmp/gma-v2a] [--frames 40] [--size 256]
                                         [--refine-steps 500] [--skip-synth] [--skip-iper] [--interleaved]
    python benchmarks/video_to_avatar.py --time-only [--frames 16] [--size 128]

Each part ends with one table of where the held-out error goes (``cause_table``; kept in
``--work``/``synth_causes.md`` and ``iper_causes.md``, and shown in docs/fitting.md): per avatar, the held-out
bbox PSNR, the mean of its worst 5 frames, and PSNR by body region of ``gma eval`` (face, hands, arms,
torso, legs, what no body face covers, and the band along the mask's outline), mask IoU and the rendered
opacity and coverage on the outline band. ``--resolutions`` and ``--steps-factors`` add rows of the refined
estimated-pose synthetic avatar fitted at other training resolutions or with more or fewer steps;
``--iper-fits on`` makes only the refined iPER fit.

    python benchmarks/video_to_avatar.py --skip-iper --frames 16 --size 128 --refine-steps 50 \
                                         [--resolutions 96 128] [--steps-factors 0.5 2]

``--time-only`` is what a user waits for: the synthetic turn's mp4 imported and fitted once (the
preset's defaults, pose refinement on as for any imported video), the held-out novel poses scored without
test-time fitting; it prints the import, fit and total seconds (``benchmarks/report.py`` runs it).

Everything lands in ``--work`` and is reused on a second run (fits resume from their checkpoints), so
an interrupted run continues. Needs MediaPipe (``pip install 'gma[video]'``) and a wgpu adapter.
Quick preset throughout; evaluation at the fit's resolution (192 px).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing
sys.path.insert(0, str(REPO / "benchmarks"))  # video_fit's joint helpers
from common import iper_clip, iper_missing  # noqa: E402

IPER = iper_clip()
KEYS = ("psnr", "psnr_bbox", "ssim_bbox", "mask_iou")


# How the clips are imported (``--per-frame``, ``--smooth-frames``: gma import video's options of the same
# names); use a separate --work for each, as the imports are reused by folder.
IMPORT = {"tracking": True, "smooth_frames": 0}


def _import(clip: Path, out: Path, focal, anny) -> dict:
    from gma.video import FitConfig, VideoImportConfig, estimate_sequence

    if (out / "video_report.json").is_file():
        return json.loads((out / "video_report.json").read_text())
    t0 = time.perf_counter()
    cfg = VideoImportConfig(focal=focal, tracking=IMPORT["tracking"],
                            fit=FitConfig(smooth_frames=IMPORT["smooth_frames"]))
    _, report = estimate_sequence(clip, out, config=cfg, anny=anny, progress=False)
    report["wall_s"] = time.perf_counter() - t0
    return report


def _fit(seq, out: Path, refine: str, body, ctx, **overrides) -> tuple[object, float]:
    from gma.avatar import Avatar
    from gma.train.config import preset
    from gma.train.trainer import OPTIONS_ADDED_SINCE, Trainer, work_dir

    cfg = preset("quick", pose={"refine": refine}, **overrides)
    metrics = work_dir(out) / "metrics.json"
    stale = False
    if out.is_file() and metrics.is_file():
        done = json.loads(metrics.read_text())
        # (a refined fit from before the pose alignment pass, or from before the twist bones were refined:
        # fit again, from the start)
        saved = json.loads((work_dir(out) / "config.json").read_text()).get("pose", {})
        bones = saved.get("bones", OPTIONS_ADDED_SINCE["pose.bones"])
        stale = "pose_refinement" in done and ((cfg.pose.align > 0 and "pose_alignment" not in done)
                                               or bones != cfg.pose.bones)
        if not stale:
            return Avatar.load(out), done["fit_seconds"]
    avatar = Trainer(cfg, seq, out, body=body, ctx=ctx, progress=False).run(resume=not stale)
    return avatar, avatar.info["fit_seconds"]


def _eval(avatar, seq, split: str, out: Path, steps: int, body, ctx) -> dict:
    from gma.train.evaluate import evaluate
    from gma.train.pose_refine import TEST_TIME_MSE, PoseRefineConfig
    from gma.train.regions import REGION_ORDER

    cached = out / f"metrics_{split}.json"
    if cached.is_file():
        res = json.loads(cached.read_text())
        # (scores from before the avatar's own body identity was used lack "identity_delta", those from
        # before coarse-to-fine test-time fitting "coarse_to_fine", those from before the squared error in its
        # loss "mse", those from before the twist bones were refined "bones": redo them)
        refined = res.get("refined", {})
        fitted = out.with_suffix(".gma")  # X.eval scores X.gma; an avatar fitted again is scored again
        newer = not fitted.is_file() or cached.stat().st_mtime >= fitted.stat().st_mtime
        regions = set(res.get("regions", {})) == set(REGION_ORDER)  # (scores from before the torso, legs, edge)
        if refined.get("steps", 0) == steps and "identity_delta" in res and newer and regions and (steps == 0 or (
                refined.get("coarse_to_fine") and refined.get("mse", 0.0) == TEST_TIME_MSE
                and refined.get("bones") == PoseRefineConfig().bones)):
            return res
    return evaluate(avatar, seq, split, out, resolution=192, body=body, ctx=ctx, images=13, use_lpips=False,
                    refine_steps=steps)


def _row(name: str, res: dict, fit_s: float | None = None) -> str:
    m, r = res["mean"], res.get("refined", {}).get("mean")
    cells = [f"{m[k]:8.2f}" if k.startswith("psnr") else f"{m[k]:8.3f}" for k in KEYS]
    if r is not None:
        cells += [f"{r[k]:8.2f}" if k.startswith("psnr") else f"{r[k]:8.3f}" for k in KEYS]
    fit = f"{fit_s:7.0f}" if fit_s is not None else "       "
    return f"  {name:<34}{fit} " + " ".join(cells)


def _scored(res: dict) -> dict:
    """The scores a table reads: after test-time pose fitting where it ran, else as evaluated."""
    return res.get("refined", res)


def cause_table(rows: list[tuple[str, dict]]) -> str:
    """A markdown table, one row per avatar (label, ``gma eval`` result): held-out bbox PSNR, its worst 5
    frames, and PSNR by region (``gma.train.regions``; "–" where no held-out frame shows the region), after
    test-time pose fitting where it ran."""
    from gma.train.regions import REGION_ORDER

    head = ["avatar", "bbox PSNR", "worst 5", *REGION_ORDER, "mask IoU", "edge opacity", "edge coverage"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for label, res in rows:
        r = _scored(res)
        regions = r["regions"]
        cells = [label, f"{r['mean']['psnr_bbox']:.2f}", f"{r['worst']['psnr_bbox']:.2f}"]
        cells += ["–" if regions[n]["psnr"] is None else f"{regions[n]['psnr']:.2f}" for n in REGION_ORDER]
        edge = [regions["edge"].get(k) for k in ("opacity", "coverage")]  # (no coverage in older scores)
        cells += [f"{r['mean']['mask_iou']:.3f}", *("–" if v is None else f"{v:.3f}" for v in edge)]
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def _print_table(title: str, rows: list[tuple[str, dict]], work: Path, name: str) -> None:
    """Print the cause and region table and keep it as ``work/name.md`` (what docs/fitting.md shows)."""
    table = f"{title}\n\n{cause_table(rows)}\n"
    (work / f"{name}.md").write_text(table)
    print(f"\n{table}  (kept in {work / (name + '.md')})")


def _header() -> str:
    cols = " ".join(f"{k:>8}" for k in KEYS)
    return f"  {'':<34}{'fit s':>7} {cols} | after test-time pose fitting: {cols}"


def _synthetic_clip(work: Path, frames: int, size: int, body, ctx):
    """The ground-truth synthetic turn and its training frames as an mp4 (made once per work folder)."""
    import imageio.v3 as iio

    from gma.data import read_sequence
    from gma.synth.generate import SynthConfig, synthesize

    gt_dir = work / "synth_gt"
    gt = read_sequence(gt_dir) if (gt_dir / "cameras.json").is_file() else synthesize(
        gt_dir, SynthConfig(width=size, height=size, train_frames=frames, test_pose_frames=8, test_view_frames=0),
        ctx=ctx, body=body, progress=False)
    clip = work / "synth_turn.mp4"
    if not clip.is_file():  # the training frames only, as a phone video would show them
        iio.imwrite(clip, np.stack([gt.image(i) for i in gt.split("train")]), fps=12, codec="libx264",
                    macro_block_size=16)
    return gt, clip


def synthetic(work: Path, frames: int, size: int, steps: int, body, ctx, resolutions=(), steps_factors=()) -> None:
    from gma.data import read_sequence

    gt, clip = _synthetic_clip(work, frames, size, body, ctx)
    report = _import(clip, work / "synth_video", float(gt.cameras.K[0, 0, 0]), body)
    est = read_sequence(work / "synth_video")
    print(f"\nsynthetic turn, {frames} frames at {size} px -> mp4 -> gma import video: mask IoU of the fitted "
          f"body {report['mask_iou_mean']:.3f}, reprojection {report.get('reprojection_error_px_mean')} px")
    print(f"  phenotype fitted {report['phenotype']}; true {np.round(gt.body.arrays['phenotype'], 3).tolist()}")
    rows, scores, causes = [], {}, []
    on_video = _true_poses_on_video(work / "synth_video_truepose", gt, work / "synth_video")
    for name, seq, refine, tag in (("true poses", gt, "off", "true"),
                                   ("true poses, the video's frames", on_video, "off", "true_on_video"),
                                   ("estimated poses, no refinement", est, "off", "estimated"),
                                   ("estimated poses, refined in the fit", est, "on", "estimated_refined")):
        avatar, fit_s = _fit(seq, work / f"synth_{tag}.gma", refine, body, ctx)
        res = _eval(avatar, gt, "test_pose", work / f"synth_{tag}.eval", steps, body, ctx)
        rows.append(_row(name, res, fit_s))
        causes.append((name, res))
        scores[tag] = _scored(res)["mean"]["psnr_bbox"]
    causes += _variant_rows(est, gt, work, steps, body, ctx, resolutions, steps_factors)
    print(f"  training-frame joints vs truth (13 COCO joints, px at {size} px): estimated {_joint_px(gt, est, None)}, "
          f"refined in the fit {_joint_px(gt, est, work / 'synth_estimated_refined.body.npz')}")
    print(f"held-out novel poses of the ground truth (true poses on each avatar's own body shape, true images, "
          f"192 px; test-time fitting {steps} steps per frame):")
    print(_header())
    print("\n".join(rows))
    print(f"  price of pose estimation (bbox PSNR after test-time fitting): estimated and refined poses "
          f"{scores['true_on_video'] - scores['estimated_refined']:.2f} dB below true poses on the same video "
          f"frames and masks, {scores['true'] - scores['estimated_refined']:.2f} dB below true poses on the "
          "original frames and masks")
    _print_table(f"Synthetic turn, {frames} training frames at {size} px, 8 held-out novel poses scored at 192 px "
                 f"after {steps} test-time pose-fitting steps per frame (quick preset unless the row says)",
                 causes, work, "synth_causes")


def _variant_rows(est, gt, work: Path, steps: int, body, ctx, resolutions, steps_factors) -> list[tuple[str, dict]]:
    """The refined estimated-pose fit again at other training resolutions and step counts (quick preset
    otherwise), scored like the others: what resolution and steps are worth."""
    from gma.train.config import preset

    quick = preset("quick")
    rows = []
    for res_px in resolutions:
        tag = f"estimated_refined_{res_px}px"
        avatar, _ = _fit(est, work / f"synth_{tag}.gma", "on", body, ctx, resolution=res_px)
        rows.append((f"estimated, refined, fit at {res_px} px",
                     _eval(avatar, gt, "test_pose", work / f"synth_{tag}.eval", steps, body, ctx)))
    for factor in steps_factors:
        s1, s2 = round(quick.stage1_steps * factor), round(quick.stage2_steps * factor)
        tag = f"estimated_refined_{s1}_{s2}steps"
        avatar, _ = _fit(est, work / f"synth_{tag}.gma", "on", body, ctx, stage1_steps=s1, stage2_steps=s2)
        rows.append((f"estimated, refined, {s1} + {s2} steps",
                     _eval(avatar, gt, "test_pose", work / f"synth_{tag}.eval", steps, body, ctx)))
    return rows


def time_only(work: Path, frames: int, size: int, body, ctx) -> None:
    """One import and one fit of the synthetic turn, timed; the held-out score beside it."""
    gt, clip = _synthetic_clip(work, frames, size, body, ctx)
    report = _import(clip, work / "synth_video", float(gt.cameras.K[0, 0, 0]), body)
    from gma.data import read_sequence

    avatar, fit_s = _fit(read_sequence(work / "synth_video"), work / "synth_estimated_refined.gma", "on", body, ctx)
    res = _eval(avatar, gt, "test_pose", work / "synth_estimated_refined.eval", 0, body, ctx)
    print(f"synthetic turn, {frames} frames at {size} px, quick preset: import {report.get('wall_s', 0.0):.0f} s, "
          f"fit {fit_s:.0f} s, video -> avatar {report.get('wall_s', 0.0) + fit_s:.0f} s; held-out bbox PSNR "
          f"{res['mean']['psnr_bbox']:.2f} dB (no test-time fitting)")


def _true_poses_on_video(out: Path, gt, est_dir: Path):
    """The imported sequence (mp4 frames, MediaPipe masks, its camera and world) with the true body: the true
    phenotype and the true training poses moved into the import's world (the same pose relative to the
    camera). An avatar fitted on it differs from the true-pose one only by what the video and the
    estimated masks cost; from the estimated-pose ones only by the poses and the shape."""
    import shutil

    from gma.body.params import SequenceBody, save_body
    from gma.data import read_sequence

    if not (out / "body.npz").is_file():
        tmp = out.with_name(out.name + ".partial")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(est_dir, tmp)
        (tmp / "video_report.json").unlink()  # not estimated poses: no refinement by default
        est = read_sequence(tmp)
        R_e, t_e = est.cameras.w2c[0][:3, :3], est.cameras.w2c[0][:3, 3]
        pose = gt.body.arrays["pose"][gt.split("train")].astype(np.float64)
        for k, i in enumerate(gt.split("train")):
            R_g, t_g = gt.cameras.w2c[i][:3, :3], gt.cameras.w2c[i][:3, 3]
            # world_est = R_e^T (R_g x + t_g - t_e): the root (the rest of the body hangs from it) moves with it
            pose[k, 0, :3, :3] = R_e.T @ R_g @ pose[k, 0, :3, :3]
            pose[k, 0, :3, 3] = R_e.T @ (R_g @ pose[k, 0, :3, 3] + t_g - t_e)
        arrays = {**est.body.arrays, "pose": pose.astype(np.float32), "phenotype": gt.body.arrays["phenotype"]}
        save_body(tmp / "body.npz", SequenceBody("anny", arrays))
        tmp.rename(out)
    return read_sequence(out)


def _joint_px(gt, est, refined_body) -> str:
    """Mean (median) pixel distance between the COCO joints of the estimated (or refined) training poses
    and the true ones, each projected through its own sequence's camera."""
    from types import SimpleNamespace

    from video_fit import JOINTS, _points_uv

    from gma.body import load_body
    from gma.body.params import load_body as load_params
    from gma.video.rig import AnnyRig

    rig = AnnyRig(load_body("anny"))
    idx = [rig.index(n) for n in JOINTS]
    src = est if refined_body is None else SimpleNamespace(body=load_params(refined_body))
    truth = _points_uv(rig, gt, gt.cameras.frame)[gt.split("train")][:, idx]
    err = np.linalg.norm(_points_uv(rig, src, est.cameras.frame)[:, idx] - truth, axis=-1)
    return f"{err.mean():.2f} ({np.median(err):.2f})"


def _refinement_rows(seq, work: Path, prefix: str, steps: int, body, ctx, variants=("off", "on")) -> dict:
    """Fit ``seq`` without and with pose refinement (those of ``variants``), score its test split, print a
    row each and the held-out bbox PSNR gain (no refinement -> refined fit + test-time fitting)."""
    results = {}
    for refine in variants:
        avatar, fit_s = _fit(seq, work / f"{prefix}_{refine}.gma", refine, body, ctx)
        results[refine] = _eval(avatar, seq, "test", work / f"{prefix}_{refine}.eval", steps, body, ctx)
        print(_row(f"fit with pose refinement {refine}", results[refine], fit_s))
    if "off" in results and "on" in results:
        base = results["off"]["mean"]["psnr_bbox"]
        best = _scored(results["on"])["mean"]["psnr_bbox"]
        print(f"  bounding-box PSNR on held-out frames: {base:.2f} dB without refinement -> {best:.2f} dB with "
              f"refinement in the fit and at test time ({best - base:+.2f} dB)")
    return results


def _interleaved_copy(seq_dir: Path, out: Path, n: int):
    """A copy of the imported iPER sequence holding out every fourth frame (frames 2, 6, 10, ...)."""
    import shutil

    from gma.data import read_sequence

    if not (out / "splits.json").is_file():
        tmp = out.with_name(out.name + ".partial")
        shutil.rmtree(tmp, ignore_errors=True)
        shutil.copytree(seq_dir, tmp)
        split = {"train": [i for i in range(n) if i % 4 != 2], "test": [i for i in range(n) if i % 4 == 2]}
        (tmp / "splits.json").write_text(json.dumps(split))
        tmp.rename(out)
    return read_sequence(out)


def _both_scores(label: str, res: dict) -> list[tuple[str, dict]]:
    """Table rows of one evaluated avatar: held-out poses as estimated, and after test-time fitting."""
    plain = {k: v for k, v in res.items() if k != "refined"}
    rows = [(f"{label}, held-out poses as estimated", plain)]
    if "refined" in res:
        rows.append((f"{label}, test-time pose fitting", res["refined"]))
    return rows


def iper(work: Path, steps: int, body, ctx, figure: Path, interleaved: bool = False,
         variants=("off", "on", "nosym")) -> None:
    from gma.data import read_sequence

    seq_dir = work / "iper"
    report = _import(IPER, seq_dir, None, body)
    n = report["frames_used"]
    split = {"train": list(range(round(n * 0.75))), "test": list(range(round(n * 0.75), n))}
    (seq_dir / "splits.json").write_text(json.dumps(split))
    seq = read_sequence(seq_dir)
    print(f"\niper_turn_512.gif: {n} frames, last {len(split['test'])} held out; video fit mask IoU "
          f"{report['mask_iou_mean']:.3f}, reprojection {report.get('reprojection_error_px_mean')} px, "
          f"phenotype {report['phenotype']}")
    print(_header())
    results = _refinement_rows(seq, work, "iper", steps, body, ctx, [v for v in ("off", "on") if v in variants])
    causes = [row for refine, res in results.items()
              for row in _both_scores(f"pose refinement {refine} in the fit", res)]
    if "off" in results and "on" in results:
        _figure(work, results, figure)
    if "nosym" in variants:
        # The left-right symmetry prior (on by default) fills in the side the turn shows less: the refined fit
        # without it, and the held-out frames side by side.
        avatar, fit_s = _fit(seq, work / "iper_on_nosym.gma", "on", body, ctx, symmetry=0.0)
        nosym = _eval(avatar, seq, "test", work / "iper_on_nosym.eval", steps, body, ctx)
        print(_row("fit with pose refinement on, --symmetry 0", nosym, fit_s))
        causes += _both_scores("refined, --symmetry 0", nosym)
        if "on" in results:
            _symmetry_figure(work, results["on"], figure.with_name("iper_symmetry.png"))
    _print_table(f"iPER turn, {n} frames at 512 px, last {len(split['test'])} held out, quick preset, scored at "
                 f"192 px; test-time pose fitting {steps} steps per frame", causes, work, "iper_causes")
    if interleaved:
        seq = _interleaved_copy(seq_dir, work / "iper_interleaved", n)
        print(f"\niper_turn_512.gif, every fourth frame held out ({len(seq.split('test'))} frames, views between "
              "training views)")
        print(_header())
        _refinement_rows(seq, work, "iper_interleaved", steps, body, ctx)


def _side_by_side(figure: Path, frames: list[int], left: Path, right: Path, columns: str) -> None:
    """Per frame a row: the held-out frame and the render of ``left`` | the render of ``right``, each cut
    from the side-by-side image ``gma eval`` writes (target | render | error); ``left`` / ``right`` are
    paths with ``{f:06d}`` for the frame."""
    import imageio.v3 as iio

    from gma.render.image_io import save_png

    rows = []
    for f in frames:
        a = iio.imread(str(left).format(f=f))
        b = iio.imread(str(right).format(f=f))
        w = a.shape[1] // 3
        rows.append(np.concatenate([a[:, :w], a[:, w:2 * w], b[:, w:2 * w]], 1))
    figure.parent.mkdir(parents=True, exist_ok=True)
    save_png(figure, np.concatenate(rows, 0)[..., :3].astype(np.float32) / 255.0)
    print(f"  wrote {figure} (columns: {columns})")


def _figure(work: Path, results: dict, figure: Path) -> None:
    """target | no refinement | refined fit + test-time pose fitting, for up to three held-out frames."""
    frames = [r["frame"] for r in results["off"]["frames"]]
    pick = [frames[i] for i in np.linspace(0, len(frames) - 1, 3).round().astype(int)]
    _side_by_side(figure, pick, work / "iper_off.eval" / "test_{f:06d}.png",
                  work / "iper_on.eval" / "test_refined_{f:06d}.png",
                  "held-out frame | avatar without refinement | refined fit + test-time pose fitting")


def _symmetry_figure(work: Path, results: dict, figure: Path) -> None:
    """target | refined fit without the symmetry prior | with it (both after test-time pose fitting), for
    the three held-out frames the clip shows least of the person's side (its first three)."""
    _side_by_side(figure, [r["frame"] for r in results["frames"]][:3],
                  work / "iper_on_nosym.eval" / "test_refined_{f:06d}.png",
                  work / "iper_on.eval" / "test_refined_{f:06d}.png",
                  "held-out frame | refined, --symmetry 0 | refined, symmetry prior on")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/gma-v2a", help="work folder (reused by a second run)")
    ap.add_argument("--frames", type=int, default=40, help="training frames of the synthetic turn")
    ap.add_argument("--size", type=int, default=256, help="synthetic image size")
    ap.add_argument("--refine-steps", type=int, default=500,
                    help="test-time pose fitting steps per frame (500: converged with the 36 refined bones, "
                         "docs/fitting.md)")
    ap.add_argument("--figure", default=str(REPO / "docs" / "iper_pose_refinement.png"))
    ap.add_argument("--skip-synth", action="store_true")
    ap.add_argument("--skip-iper", action="store_true")
    ap.add_argument("--interleaved", action="store_true",
                    help="also fit and score the iPER clip with every fourth frame held out")
    ap.add_argument("--iper-fits", default="off,on,nosym",
                    help="which iPER fits to make: off (no pose refinement), on (refined), nosym (refined, "
                         "--symmetry 0); comma-separated")
    ap.add_argument("--resolutions", type=int, nargs="*", default=[],
                    help="also fit the refined estimated-pose synthetic avatar at these training resolutions")
    ap.add_argument("--steps-factors", type=float, nargs="*", default=[],
                    help="also fit it with the quick preset's steps times these factors")
    ap.add_argument("--per-frame", action="store_true", help="import with MediaPipe detecting each frame on its own")
    ap.add_argument("--smooth-frames", type=int, default=0, help="import with the landmarks smoothed over N frames")
    ap.add_argument("--time-only", action="store_true",
                    help="only import and fit the synthetic turn once, timed (no iPER, no other fits)")
    args = ap.parse_args(argv)
    IMPORT.update(tracking=not args.per_frame, smooth_frames=args.smooth_frames)
    torch.set_num_threads(1)  # torch and lavapipe share the cores (see gma fit --threads)

    from gma.body import load_body
    from gma.gpu import GpuContext

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    body, ctx = load_body("anny"), GpuContext.create()
    t0 = time.perf_counter()
    if args.time_only:
        time_only(work, args.frames, args.size, body, ctx)
        return 0
    if not args.skip_iper:
        if IPER.is_file():
            iper(work, args.refine_steps, body, ctx, Path(args.figure), args.interleaved,
                 [v for v in args.iper_fits.split(",") if v])
        else:
            print(f"skipped: {iper_missing(IPER)}")
    if not args.skip_synth:
        synthetic(work, args.frames, args.size, args.refine_steps, body, ctx, args.resolutions, args.steps_factors)
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    sys.exit(main())
