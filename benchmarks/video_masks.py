#!/usr/bin/env python3
"""Person masks of `gma import video`, against ground truth (issue 12): MediaPipe's masks as they are and
checked against the clip's background plate (``gma.video.matte``).

A ``gma synth`` turn (true masks known) is composited over a real room — the background of
iPER turn clip (``common.iper_clip()``), taken from that clip by the same plate estimate — written to an mp4
as a phone would, decoded, and MediaPipe run on it. Printed: mask IoU (at one half) and mean absolute
error of the soft mask against the true masks, over all frames and inside the person's bounding box, for
MediaPipe's masks and the refined ones (with ``--size`` above 1280, also the check run at full size rather
than on frames shrunk to 1280 px, and both times); then the same refinement on the iPER clip itself (no ground truth:
what it changed) and a picture, ``--figure`` (default docs/video_masks.png): iPER frames, MediaPipe's mask
and its composite over grey | the refined mask and its composite.

    python benchmarks/video_masks.py [--work /tmp/gma-vmask] [--frames 40] [--size 256]

Needs MediaPipe (``pip install 'gma[video]'``). ``GMA_BENCH_SMOKE=1`` (the test suite) checks that the
script starts and its inputs exist, and stops.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing
sys.path.insert(0, str(REPO / "benchmarks"))
from common import iper_clip, iper_missing  # noqa: E402

IPER = iper_clip()


def _scores(masks: np.ndarray, truth: np.ndarray) -> dict:
    """IoU at one half and mean absolute error, over whole frames and inside the true person's box."""
    from gma.video.report import mask_iou

    ious, mae, mae_box = [], [], []
    for m, g in zip(masks, truth, strict=True):
        b = g > 0.5
        ious.append(mask_iou(m > 0.5, b))
        mae.append(np.abs(m - g).mean())
        ys, xs = np.nonzero(b)
        if ys.size:
            box = (slice(ys.min(), ys.max() + 1), slice(xs.min(), xs.max() + 1))
            mae_box.append(np.abs(m[box] - g[box]).mean())
    return {"iou": float(np.mean(ious)), "mae": float(np.mean(mae)), "mae_box": float(np.mean(mae_box))}


def _iper(work: Path):
    """The iPER clip's frames and MediaPipe masks (detection cached in ``work``)."""
    from gma.video.detect import detect_frames
    from gma.video.frames import read_video

    frames, _ = read_video(IPER)
    det, _ = detect_frames(frames, work / "iper_detect", progress=False)
    return frames, det.masks


def synthetic(work: Path, frames: int, size: int, room: np.ndarray) -> None:
    import imageio.v3 as iio

    from gma.body import load_body
    from gma.data import read_sequence
    from gma.gpu import GpuContext
    from gma.synth.generate import SynthConfig, synthesize
    from gma.video.detect import detect_frames
    from gma.video.matte import MatteConfig, refine_masks

    gt_dir = work / "synth_gt"
    gt = read_sequence(gt_dir) if (gt_dir / "cameras.json").is_file() else synthesize(
        gt_dir, SynthConfig(width=size, height=size, train_frames=frames, test_pose_frames=0, test_view_frames=0),
        ctx=GpuContext.create(), body=load_body("anny"), progress=False)
    idx = gt.split("train")
    truth = np.stack([gt.mask(i) for i in idx])
    # The synthetic frames are rendered over grey 0.5 (SynthConfig's default): take the person out and put
    # the room behind it.
    plate = np.asarray(iio.imread(work / "room.png"), np.float32)[..., :3] / 255.0 if (work / "room.png").is_file() \
        else None
    if plate is None:
        from PIL import Image

        plate = np.asarray(Image.fromarray(room).resize((size, size), Image.BILINEAR), np.float32) / 255.0
        iio.imwrite(work / "room.png", (plate * 255).round().astype(np.uint8))
    images = np.stack([gt.image(i) for i in idx]).astype(np.float32) / 255.0
    composite = images - 0.5 * (1 - truth[..., None]) + plate[None] * (1 - truth[..., None])
    clip = work / "synth_room.mp4"
    if not clip.is_file():
        iio.imwrite(clip, (np.clip(composite, 0, 1) * 255).round().astype(np.uint8), fps=12, codec="libx264",
                    macro_block_size=16)
    video = np.stack(list(iio.imiter(clip)))[..., :3]
    det, _ = detect_frames(video, work / "synth_detect", progress=False)
    t0 = time.perf_counter()
    refined, report = refine_masks(video, det.masks)
    secs = time.perf_counter() - t0
    rows = [("MediaPipe", det.masks, None), ("checked against plate", refined, secs)]
    if size > MatteConfig.work_side:  # the check on shrunk frames against the check at full size
        t0 = time.perf_counter()
        full, _ = refine_masks(video, det.masks, MatteConfig(work_side=size))
        rows.append(("checked at full size", full, time.perf_counter() - t0))
    print(f"synthetic turn ({len(idx)} frames, {size} px) over the iPER room, mp4, MediaPipe; true masks known")
    print(f"  {'masks':<22} {'IoU':>7} {'MAE':>8} {'MAE in box':>11} {'check, s':>9}")
    for name, m, t in rows:
        s = _scores(m, truth)
        print(f"  {name:<22} {s['iou']:7.3f} {s['mae']:8.4f} {s['mae_box']:11.4f} {'' if t is None else f'{t:9.1f}'}")
    print(f"  refinement {secs:.1f} s: {json.dumps(report)}")


def iper_figure(frames: np.ndarray, masks: np.ndarray, refined: np.ndarray, figure: Path, pick=(5, 16, 44)) -> None:
    from gma.render.image_io import save_png

    rows = []
    for t in pick:
        img = frames[t].astype(np.float32) / 255.0
        ys, xs = np.nonzero(masks[t] > 0.5)
        box = (slice(max(ys.min() - 16, 0), ys.max() + 16), slice(max(xs.min() - 32, 0), xs.max() + 32))
        cells = []
        for m in (masks[t], refined[t]):
            cells += [np.repeat(m[..., None], 3, -1)[box], (img * m[..., None] + 0.5 * (1 - m[..., None]))[box]]
        rows.append(np.concatenate(cells, 1))
    h = max(r.shape[0] for r in rows)
    rows = [np.pad(r, ((0, h - r.shape[0]), (0, 4), (0, 0)), constant_values=1.0) for r in rows]
    figure.parent.mkdir(parents=True, exist_ok=True)
    save_png(figure, np.concatenate(rows, 1))
    print(f"  wrote {figure} (per frame: MediaPipe's mask, composite | refined mask, composite)")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--work", default="/tmp/gma-vmask", help="work folder (reused by a second run)")
    ap.add_argument("--frames", type=int, default=40, help="frames of the synthetic turn")
    ap.add_argument("--size", type=int, default=256, help="synthetic image size")
    ap.add_argument("--figure", default=str(REPO / "docs" / "video_masks.png"))
    args = ap.parse_args(argv)
    if not IPER.is_file():
        print(iper_missing(IPER), file=sys.stderr)
        return 2
    if os.environ.get("GMA_BENCH_SMOKE"):
        from gma.video.matte import refine_masks  # noqa: F401  (the module imports)

        print("smoke mode: inputs found, stopping before MediaPipe")
        return 0
    from gma.video.matte import background_plate, refine_masks

    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    frames, masks = _iper(work)
    t0 = time.perf_counter()
    refined, report = refine_masks(frames, masks)
    secs = time.perf_counter() - t0
    plate, views, _ = background_plate(frames, masks)
    # Where the person always stood the room is unknown: fill it from the nearest known pixel.
    from scipy.ndimage import distance_transform_edt

    _, (iy, ix) = distance_transform_edt(views < 3, return_indices=True)
    room = (plate[iy, ix] * 255).round().astype(np.uint8)
    synthetic(work, args.frames, args.size, room)
    print(f"\niper_turn_512.gif ({len(frames)} frames, {frames.shape[2]}x{frames.shape[1]}): refinement "
          f"{secs:.1f} s, {json.dumps(report)}")
    iper_figure(frames, masks, refined, Path(args.figure))
    return 0


if __name__ == "__main__":
    sys.exit(main())
