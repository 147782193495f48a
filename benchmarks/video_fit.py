"""Figures for the video pipeline (issue 8): seconds per frame of each stage of ``gma import video``
on a synthetic clip with known truth, the fit's joint error against that truth and its mask IoU, and
(with ``--iper``) the same run on the real iPER clip (``common.iper_clip()``; docs/data.md says where to
get it).

    python benchmarks/video_fit.py [--frames 24] [--size 256] [--threads 2] [--sheet docs/video_contact_sheet.png]
                                   [--iper] [--iper-sheet docs/video_iper_contact_sheet.png]

Needs MediaPipe (``pip install 'gma[video]'``) and a wgpu adapter (lavapipe is enough) for the
synthetic clip. Each run starts from an empty work directory, so nothing is reused.
"""

from __future__ import annotations

import argparse
import json
import shutil
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import roma
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # run from a checkout without installing
sys.path.insert(0, str(REPO / "benchmarks"))
from common import iper_clip, iper_missing  # noqa: E402

IPER = iper_clip()
JOINTS = ["coco:left_shoulder", "coco:right_shoulder", "coco:left_elbow", "coco:right_elbow", "coco:left_wrist",
          "coco:right_wrist", "coco:left_hip", "coco:right_hip", "coco:left_knee", "coco:right_knee",
          "coco:left_ankle", "coco:right_ankle", "coco:nose"]


def _points_uv(rig, seq, frame_cams) -> np.ndarray:
    """Pixels [T, P, 2] of the rig's points for a sequence's body, through ``frame_cams(t)`` -> (K, w2c)."""
    from gma.video.fit import project

    pose = torch.as_tensor(seq.body.arrays["pose"]).float()
    rest = rig.rest(torch.as_tensor(seq.body.arrays["phenotype"]).float())
    with torch.no_grad():
        pts = rig.points(rig.transforms(pose, rest), rest)
    out = []
    for t in range(len(pose)):
        K, w2c = (torch.as_tensor(a).float() for a in frame_cams(t))
        out.append(project(pts[t], K, w2c[:3, :3], w2c[:3, 3]).numpy())
    return np.stack(out)


def _orientation_errors(body, est, gt) -> tuple[float, float]:
    """Mean errors (degrees) of two orientations against the truth, over the frames:

    - the root's, in the body's frame, around its mean: a constant offset commutes with a turn in place
      and costs the avatar nothing, what varies from frame to frame blurs it;
    - the head's relative to the upper spine (a head turned against the torso)."""
    def rotations(seq, frames):
        pose = seq.body.arrays["pose"][frames]
        shape = torch.as_tensor(seq.body.arrays["phenotype"]).float()
        spine, head = body.bone_index("spine01"), body.bone_index("head")
        rel = []
        with torch.no_grad():
            for p in pose:
                g = body.bone_transforms(body.check_params({"pose": torch.as_tensor(p), "shape": shape})).double()
                rel.append((g[spine, :3, :3].T @ g[head, :3, :3]).numpy())
        cams = np.stack([seq.cameras.frame(i)[1][:3, :3] for i in frames])
        return cams @ pose[:, 0, :3, :3].astype(np.float64), np.stack(rel)

    frames = list(range(len(gt)))
    root_e, head_e = rotations(est, frames)
    root_g, head_g = rotations(gt, frames)
    err = np.swapaxes(root_g, -1, -2) @ root_e                      # body-frame root error per frame
    u, _, vt = np.linalg.svd(err.sum(0))
    mean = u @ vt                                                    # its mean rotation (chordal)
    root = roma.rotmat_geodesic_distance(torch.from_numpy(err), torch.from_numpy(mean)).rad2deg().mean()
    head = roma.rotmat_geodesic_distance(torch.from_numpy(head_e), torch.from_numpy(head_g)).rad2deg().mean()
    return float(root), float(head)


def _run(clip: Path, out: Path, focal, anny, sheet: str | None):
    from gma.video import VideoImportConfig, estimate_sequence

    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(out.parent / (out.name + ".work"), ignore_errors=True)
    t0 = time.perf_counter()
    seq, report = estimate_sequence(clip, out, config=VideoImportConfig(focal=focal), anny=anny, progress=False)
    total = time.perf_counter() - t0
    if sheet:
        Path(sheet).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "video_contact_sheet.png", sheet)
    return seq, report, total


def _print_stages(name: str, report: dict, total: float) -> None:
    t = report["frames_used"]
    secs = dict(report["seconds"])
    print(f"\n{name}: {t} frames, total {total:.1f} s ({total / t:.2f} s/frame)")
    print(f"  {'stage':<10}{'s total':>10}{'s/frame':>10}")
    for k, v in secs.items():
        print(f"  {k:<10}{v:>10.2f}{v / t:>10.3f}")
    print(f"  detection rate {report['detection_rate']:.3f}, interpolated {report['frames_interpolated']}, "
          f"swapped {report.get('frames_swapped_left_right')}, frames with hands {report['frames_with_hands']}")
    print(f"  reprojection error vs landmarks {report.get('reprojection_error_px_mean')} px, "
          f"mask IoU (fitted body vs mask) {report['mask_iou_mean']:.3f}, phenotype {report['phenotype']}")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--threads", type=int, default=2)
    ap.add_argument("--sheet", default=None, help="copy the synthetic clip's contact sheet here")
    ap.add_argument("--iper", action="store_true", help="also run on the iPER clip (docs/data.md)")
    ap.add_argument("--iper-sheet", default=None, help="copy the iPER clip's contact sheet here")
    args = ap.parse_args(argv)
    torch.set_num_threads(args.threads)

    import imageio.v3 as iio

    from gma.body import load_body
    from gma.synth.generate import SynthConfig, synthesize
    from gma.video.report import mask_iou
    from gma.video.rig import AnnyRig

    anny = load_body("anny")
    rig = AnnyRig(anny)
    idx = [rig.index(n) for n in JOINTS]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        gt = synthesize(tmp / "gt", SynthConfig(width=args.size, height=args.size, train_frames=args.frames,
                                                test_pose_frames=0, test_view_frames=0, texture_size=1024),
                        body=anny, progress=False)
        clip = tmp / "clip.mp4"
        iio.imwrite(clip, np.stack([gt.image(i) for i in range(len(gt))]), fps=12, codec="libx264",
                    macro_block_size=16)
        seq, report, total = _run(clip, tmp / "seq", float(gt.cameras.K[0, 0, 0]), anny, args.sheet)
        _print_stages(f"synthetic turn ({args.size} px, true focal)", report, total)
        err = np.linalg.norm(_points_uv(rig, seq, seq.cameras.frame)[:, idx]
                             - _points_uv(rig, gt, gt.cameras.frame)[:, idx], axis=-1)
        ious = [mask_iou(seq.mask(i) > 0.5, gt.mask(i) > 0.5) for i in range(len(gt))]
        print(f"  vs truth: joint error mean {err.mean():.2f} px, median {np.median(err):.2f}, "
              f"90th pct {np.percentile(err, 90):.2f} px; MediaPipe mask IoU vs true mask {np.mean(ious):.3f}")
        root, head = _orientation_errors(anny, seq, gt)
        print(f"  root orientation error around its mean {root:.2f} deg, head-to-spine error {head:.2f} deg")
        print(f"  true phenotype {np.round(gt.body.arrays['phenotype'], 3).tolist()}")
    if args.iper:
        if not IPER.is_file():
            print(f"\nskipped: {iper_missing(IPER)}")
        else:
            with tempfile.TemporaryDirectory() as tmp:
                _, report, total = _run(IPER, Path(tmp) / "seq", None, anny, args.iper_sheet)
                _print_stages("iper_turn_512.gif (default focal)", report, total)
                print(json.dumps({"mask_iou_per_frame": report["mask_iou_per_frame"]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
