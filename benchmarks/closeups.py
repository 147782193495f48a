"""Held-out frames where people look: target | avatar A | avatar B, each frame whole and its face and a hand
enlarged, as one picture (a before/after of two fits of one sequence).

The face and hand boxes come from the region map ``gma eval`` scores by (:class:`gma.train.regions.RegionMapper`:
the posed body's head and hand faces at the frame's camera); the hand shown is the one with more visible
pixels. Both avatars are posed as ``gma eval`` poses them (the frame's pose on the avatar's own body), or,
with ``--refine-steps N``, after test-time pose fitting as ``gma eval --refine-poses N`` does.

    python benchmarks/closeups.py SEQUENCE BEFORE.gma AFTER.gma --out docs/closeups.png
                                  [--split test] [--frames 40 46 52] [--resolution 384] [--refine-steps 0]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # run from a checkout without installing

ZOOM_PX = 160  # side of each enlarged face or hand crop in the picture


def _box(where: np.ndarray, margin: float = 0.35) -> tuple[int, int, int, int] | None:
    """A square (y0, y1, x0, x1) around the True pixels of ``where`` with ``margin`` of its side around them,
    kept inside the image; None when there are none."""
    ys, xs = np.nonzero(where)
    if len(ys) == 0:
        return None
    h, w = where.shape
    side = int(max(ys.max() - ys.min(), xs.max() - xs.min()) * (1 + 2 * margin)) + 8
    side = min(side, h, w)
    cy, cx = (ys.min() + ys.max()) // 2, (xs.min() + xs.max()) // 2
    y0 = int(np.clip(cy - side // 2, 0, h - side))
    x0 = int(np.clip(cx - side // 2, 0, w - side))
    return y0, y0 + side, x0, x0 + side


def _zoom(image: np.ndarray, box) -> np.ndarray:
    """The ``box`` of ``image`` [H, W, 3] enlarged to ZOOM_PX (nearest pixel: the picture shows the pixels
    the avatar renders, not a smoothed version); grey where there is no box."""
    if box is None:
        return np.full((ZOOM_PX, ZOOM_PX, 3), 0.5, np.float32)
    y0, y1, x0, x1 = box
    crop = image[y0:y1, x0:x1]
    idx = (np.arange(ZOOM_PX) * crop.shape[0] / ZOOM_PX).astype(int)
    return crop[idx][:, idx]


def _fit_height(image: np.ndarray, height: int) -> np.ndarray:
    idx_y = (np.arange(height) * image.shape[0] / height).astype(int)
    width = round(image.shape[1] * height / image.shape[0])
    idx_x = (np.arange(width) * image.shape[1] / width).astype(int)
    return image[idx_y][:, idx_x]


def _renders(avatar_path: Path, seq, split: str, picks: list[int] | None, resolution: int, refine_steps: int,
             body, ctx):
    """The frames ``picks`` (sequence frame numbers; None: three, spread) of ``split``: (frames, [T, H, W, 3]
    targets, renders, posed body vertices) for one avatar."""
    from gma.avatar import Avatar
    from gma.body.skinning import linear_blend_skinning
    from gma.train.data import load_frames
    from gma.train.evaluate import fitted_resolution
    from gma.train.pose_refine import PoseRefineConfig, refine_frozen
    from gma.train.render_step import render_frame

    avatar = Avatar.load(avatar_path)
    frames = load_frames(seq, body, split, resolution, identity=avatar.shape)
    picks = picks or [frames.indices[i] for i in np.linspace(0, len(frames) - 1, 3).round().astype(int)]
    missing = sorted(set(picks) - set(frames.indices))
    if missing:
        raise ValueError(f"--frames {' '.join(map(str, missing))}: not in split {split!r}")
    keep = [frames.indices.index(f) for f in picks]
    frames = frames.subset(keep)
    with torch.no_grad():
        decoded = avatar.decode()
    bones = frames.bones
    if refine_steps > 0:
        small = load_frames(seq, body, split, min(fitted_resolution(avatar), resolution),
                            identity=avatar.shape).subset(keep)
        corr = refine_frozen(decoded, body, small, refine_steps, PoseRefineConfig(), 1.0, ctx)
        with torch.no_grad():
            bones = body.bone_transforms({"pose": corr.all_poses(), "shape": frames.shape})
    targets, renders, posed = [], [], []
    with torch.no_grad():
        for t in range(len(frames)):
            out, _ = render_frame(decoded, body, frames, t, 1.0, ctx, cull=False, bones=bones[t])
            renders.append(out.color.clamp(0, 1).numpy())
            targets.append(frames.target(t, 1.0).numpy())
            posed.append(linear_blend_skinning(frames.rest[t], body.skin_indices, body.skin_weights, bones[t]))
    return frames, np.stack(targets), np.stack(renders), posed


def _row(target, before, after, regions, height: int) -> np.ndarray:
    """One frame: the three whole images, then face and hand enlarged (target, before, after each)."""
    hands = regions["hands"]
    face_box, hand_box = _box(regions["face"]), _box(_larger_part(hands))
    whole = [_fit_height(x, height) for x in (target, before, after)]
    zooms = [_fit_height(_zoom(x, b), height) for b in (face_box, hand_box) for x in (target, before, after)]
    gap = np.ones((height, 6, 3), np.float32)
    parts = []
    for k, p in enumerate(whole + zooms):
        parts += [p, gap] if k not in (2, 5) else [p, gap, gap, gap]
    return np.concatenate(parts[:-1], 1)


def _larger_part(mask: np.ndarray) -> np.ndarray:
    """Of a two-handed mask, the connected half with more pixels (split at the widest gap in x)."""
    ys, xs = np.nonzero(mask)
    if len(xs) < 2:
        return mask
    order = np.sort(np.unique(xs))
    gaps = np.diff(order)
    if gaps.max() <= 2:
        return mask
    cut = order[np.argmax(gaps)]
    left = mask.copy()
    left[:, cut + 1:] = False
    right = mask & ~left
    return left if left.sum() >= right.sum() else right


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("sequence")
    ap.add_argument("before", help="avatar A (.gma)")
    ap.add_argument("after", help="avatar B (.gma)")
    ap.add_argument("--out", required=True, help="the picture (.png)")
    ap.add_argument("--split", default="test")
    ap.add_argument("--frames", type=int, nargs="+", help="sequence frame numbers (default: three, spread)")
    ap.add_argument("--resolution", type=int, default=384)
    ap.add_argument("--refine-steps", type=int, default=0, help="test-time pose fitting steps per frame")
    args = ap.parse_args(argv)
    for path in (args.sequence, args.before, args.after):
        if not Path(path).exists():
            ap.exit(2, f"{path}: no such file or folder\n")
    if not 16 <= args.resolution <= 2048 or args.refine_steps < 0:
        ap.exit(2, "--resolution must lie in [16, 2048] and --refine-steps be >= 0\n")

    from gma.body import load_body
    from gma.data import read_sequence
    from gma.gpu import get_context
    from gma.render.image_io import save_png
    from gma.train.regions import RegionMapper

    seq, ctx = read_sequence(args.sequence), get_context()
    body = load_body(seq.body.model)
    try:
        frames, targets, before, posed = _renders(Path(args.before), seq, args.split, args.frames,
                                                  args.resolution, args.refine_steps, body, ctx)
    except ValueError as exc:
        ap.exit(2, f"{exc}\n")
    _, _, after, _ = _renders(Path(args.after), seq, args.split, frames.indices, args.resolution,
                              args.refine_steps, body, ctx)
    mapper = RegionMapper(ctx, body)
    rows = []
    for t in range(len(frames)):
        regions = mapper.maps(posed[t], frames.w2c[t], frames.K[t], frames.masks[t])
        rows += [_row(targets[t], before[t], after[t], regions, ZOOM_PX), np.ones((6, 1, 3), np.float32)]
    width = max(r.shape[1] for r in rows)
    picture = np.concatenate([np.pad(r, ((0, 0), (0, width - r.shape[1]), (0, 0)), constant_values=1.0)
                              for r in rows[:-1]], 0)
    save_png(Path(args.out), picture)
    print(f"wrote {args.out} (per frame: target | {Path(args.before).name} | {Path(args.after).name}, "
          f"then the face and a hand enlarged in the same order; frames {frames.indices})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
