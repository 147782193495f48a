"""Pose refinement on constructed cases: how much each of its parts pulls a known, injected pose error back.
The comparisons here depend on float rounding through a briefly fitted avatar on a 64 px frame (they
differ between machines, and flip on some), so they are figures to read, not test assertions;
tests/test_pose_refine.py keeps what holds everywhere.

1. Fit-time refinement, with and without the end-of-stage-1 alignment pass (``--pose.align``): four
   training frames show one image; frames 1 and 3 carry a root turn and shift. Root error (degrees, cm)
   as given, after the joint steps alone and with the pass.
2. Test-time fitting of one perturbed frame against a frozen avatar: with the squared colour error
   (TEST_TIME_MSE) against the plain L1 + SSIM loss: PSNR and root error of each.
3. Test-time fitting of twisted hip / shoulder / thigh / upper-arm bones: the default bone set ("body")
   against the video fit's ("video"): PSNR of each.

    python benchmarks/pose_refine.py [--size 64] [--fit-steps 120] [--refine-steps 25]
"""

from __future__ import annotations

import argparse
import copy
import json
import shutil
import tempfile
from pathlib import Path

import numpy as np


def root_error(poses, truth) -> tuple[float, float]:
    """Mean root rotation error (degrees) and root position error (cm) of [T, J, 4, 4] poses."""
    import roma

    ang = roma.rotmat_geodesic_distance(poses[:, 0, :3, :3], truth[:, 0, :3, :3]).rad2deg()
    return float(ang.mean()), float((poses[:, 0, :3, 3] - truth[:, 0, :3, 3]).norm(dim=-1).mean() * 100)


def perturb_root(pose: np.ndarray, frames, angle: float = 0.1, shift: float = 0.02) -> np.ndarray:
    """``pose`` with the root of ``frames`` turned by ±``angle`` about the vertical and moved ±``shift``."""
    import roma
    import torch

    out = pose.copy()
    for k, i in enumerate(frames):
        sgn = 1 if k % 2 == 0 else -1
        r = roma.rotvec_to_rotmat(torch.tensor([0.0, 0.0, angle * sgn])).numpy()
        out[i, 0, :3, :3] = r @ out[i, 0, :3, :3]
        out[i, 0, 0, 3] += shift * sgn
    return out


def _repeated_sequence(seq, root: Path):
    """Frames 0-3 all show frame 0, frames 1 and 3 with an injected root error: (sequence, true poses)."""
    import torch

    from gma.body.params import save_body
    from gma.data import read_sequence

    shutil.copytree(seq.root, root)
    for d in ("images", "masks"):
        for i in (1, 2, 3):
            shutil.copy(root / d / "000000.png", root / d / f"{i:06d}.png")
    cams = json.loads((root / "cameras.json").read_text())
    cams["w2c"][1:4] = [cams["w2c"][0]] * 3
    (root / "cameras.json").write_text(json.dumps(cams))
    arrays = {k: np.array(v) for k, v in seq.body.arrays.items()}
    arrays["pose"][1:4] = arrays["pose"][0]
    truth = arrays["pose"].copy()
    arrays["pose"] = perturb_root(truth, [1, 3])
    save_body(root / "body.npz", type(seq.body)("anny", arrays))
    return read_sequence(root), torch.as_tensor(truth[:4])


def _fit(seq, out: Path, body, ctx, size: int, **kw):
    from gma.train.config import preset
    from gma.train.trainer import Trainer

    tiny = dict(resolution=size, checkpoint_every=1000, log_every=1000, preview_every=0, stage2_steps=0,
                avatar={"feature_dim": 8, "fine_per_face": 1})
    cfg = preset("quick", **{**tiny, "pose": {"refine": "on", "smooth": 0.0, "prior": 0.1}, **kw})
    return Trainer(cfg, seq, out, body=body, ctx=ctx, progress=False).run()


def alignment_pass(seq, work: Path, body, ctx, args) -> None:
    import torch

    from gma.body.params import load_body
    from gma.train.trainer import refined_body_path

    rep, truth = _repeated_sequence(seq, work / "repeated")
    before = root_error(torch.as_tensor(rep.body.arrays["pose"][:4]), truth)
    print(f"1. fit-time refinement, root error as given: {before[0]:.2f} deg, {before[1]:.2f} cm")
    for align in (0, args.align_steps):
        out = work / f"align{align}.gma"
        _fit(rep, out, body, ctx, args.size, stage1_steps=args.align_fit_steps, stage2_steps=2,
             pose={"refine": "on", "smooth": 0.0, "prior": 0.1, "align": align, "bones": "video"})
        err = root_error(torch.as_tensor(load_body(refined_body_path(out)).arrays["pose"][:4]), truth)
        label = "joint steps alone" if align == 0 else f"with a {align}-step alignment pass"
        print(f"   {label}: {err[0]:.2f} deg, {err[1]:.2f} cm")


def _frozen_frame(seq, work: Path, body, ctx, args):
    """(decoded avatar fitted on trusted poses, its first training frame, a PSNR function of poses)."""
    import torch

    from gma.train.data import load_frames
    from gma.train.evaluate import _score

    avatar = _fit(seq, work / "frozen.gma", body, ctx, args.size, pose={"refine": "off"},
                  stage1_steps=args.fit_steps)
    with torch.no_grad():
        decoded = avatar.decode()
    frames = load_frames(seq, body, "train", args.size)
    frames = type(frames)(**{k: (v[[0]] if torch.is_tensor(v) and k != "shape" else v)
                             for k, v in vars(frames).items()})
    frames.indices = [frames.indices[0]]

    def psnr(poses) -> float:
        bones = body.bone_transforms({"pose": poses, "shape": frames.shape})
        return _score(decoded, body, frames, bones, 0.5, ctx, None, None, "x", 0)[0]["psnr"]

    return decoded, frames, psnr


def test_time_mse(decoded, frames, psnr, body, ctx, args) -> None:
    import torch

    from gma.train.pose_refine import BONE_SETS, PoseCorrections, PoseRefineConfig, fit_corrections, refine_frozen

    truth = frames.poses.clone()
    frames = copy.copy(frames)
    frames.poses = torch.as_tensor(perturb_root(truth.numpy(), [0]))
    cfg = PoseRefineConfig(bones="video")
    with_mse = refine_frozen(decoded, body, frames, args.refine_steps, cfg, 0.5, ctx).all_poses()
    plain = PoseCorrections(body, frames.poses, frames.indices, BONE_SETS["video"])
    fit_corrections(plain, decoded, body, frames, args.refine_steps, cfg, 0.5, ctx, mse=0.0)
    print("2. test-time fitting of a perturbed frame:")
    for label, poses in (("as perturbed", frames.poses), ("L1 + SSIM", plain.all_poses()),
                         ("L1 + SSIM + MSE (default)", with_mse)):
        deg, cm = root_error(poses, truth)
        print(f"   {label:26s} PSNR {psnr(poses):6.2f} dB, root error {deg:.2f} deg, {cm:.2f} cm")


def twist_bones(decoded, frames, psnr, body, ctx, args) -> None:
    import roma
    import torch

    from gma.train.pose_refine import PoseRefineConfig, refine_frozen

    wrong = frames.poses.clone()
    for name, rotvec in (("pelvis.L", (0.0, 0.25, 0.0)), ("upperleg02.L", (0.0, 0.0, 0.5)),
                         ("shoulder01.R", (0.25, 0.0, 0.0)), ("upperarm02.R", (0.5, 0.0, 0.0))):
        j = body.bone_index(name)
        wrong[0, j, :3, :3] = roma.rotvec_to_rotmat(torch.tensor(rotvec)) @ wrong[0, j, :3, :3]
    frames = copy.copy(frames)
    frames.poses = wrong
    print("3. test-time fitting of twisted bones:")
    print(f"   as twisted: PSNR {psnr(wrong):6.2f} dB")
    for bones in ("body", "video"):
        poses = refine_frozen(decoded, body, frames, args.refine_steps, PoseRefineConfig(bones=bones), 0.5,
                              ctx).all_poses()
        print(f"   bone set {bones!r}: PSNR {psnr(poses):6.2f} dB")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--size", type=int, default=64, help="frame size in pixels (synthesis and fitting)")
    p.add_argument("--fit-steps", type=int, default=120, help="stage-1 steps of the frozen avatar (parts 2, 3)")
    p.add_argument("--align-fit-steps", type=int, default=30, help="stage-1 steps of the fits of part 1")
    p.add_argument("--align-steps", type=int, default=20, help="steps per frame of the alignment pass")
    p.add_argument("--refine-steps", type=int, default=25, help="test-time fitting steps")
    p.add_argument("--seed", type=int, default=0)
    args = p.parse_args()
    for name in ("size", "fit_steps", "align_fit_steps", "align_steps", "refine_steps"):
        if getattr(args, name) < 1:
            p.error(f"--{name.replace('_', '-')} must be at least 1")

    from common import machine

    from gma.body import load_body
    from gma.gpu import get_context
    from gma.synth.generate import SynthConfig, synthesize

    ctx, body = get_context(), load_body("anny")
    print(machine())
    with tempfile.TemporaryDirectory(prefix="gma-pose-refine-") as tmp:
        work = Path(tmp)
        cfg = SynthConfig(width=args.size, height=args.size, train_frames=4, test_pose_frames=2,
                          test_view_frames=1, supersample=1, texture_size=256, seed=args.seed)
        seq = synthesize(work / "seq", cfg, ctx=ctx, body=body, progress=False)
        alignment_pass(seq, work, body, ctx, args)
        decoded, frames, psnr = _frozen_frame(seq, work, body, ctx, args)
        test_time_mse(decoded, frames, psnr, body, ctx, args)
        twist_bones(decoded, frames, psnr, body, ctx, args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
