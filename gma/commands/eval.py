"""``gma eval avatar.gma SEQ --split test``: PSNR / SSIM over the image and inside the person's bounding
box (/ LPIPS when its weights are installed) and mask IoU of the rendered alpha, per frame and mean,
written as JSON and a table, with side-by-side images (target | render | error ×4). An avatar that
records what its training frames saw (``gma fit`` does) also gets ``seen.png``: its mesh from the front,
back, left and right, green where the frames saw it, magenta where its look was filled in (guessed).

``--refine-poses N`` also fits each evaluated frame's pose to its image for N steps with the avatar
frozen (the PeopleSnapshot protocol of Anim-NeRF / InstantAvatar, for sequences whose poses were
estimated) and reports those scores beside the unrefined ones."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    from gma.train.config import BONE_SET_NAMES, PoseRefineConfig

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
    p.add_argument("--refine-poses", type=int, default=0, metavar="N",
                   help="test-time pose fitting: N steps per frame with the avatar frozen (0: off; the gain flattens "
                        "by about 500, docs/fitting.md; a minute or more a frame on a CPU)")
    p.add_argument("--refine-resolution", type=int, default=0,
                   help="longest image side the test-time pose fitting renders at (0: the one the avatar was "
                        "fitted at)")
    p.add_argument("--refine-bones", choices=BONE_SET_NAMES, default=PoseRefineConfig().bones,
                   help="bones the test-time pose fitting corrects: body (also the limbs' twist bones, shoulders, "
                        "hips) or video (the ones the video fit estimates), as --pose.bones of gma fit")
    p.add_argument("--refine-colour", choices=("auto", "on", "off"), default="auto",
                   help="with --refine-poses, also fit each frame's colour transform (a gain and an offset per "
                        "channel: the camera's exposure and white balance); auto: when the avatar was fitted "
                        "with them (gma fit --colour.refine)")
    p.add_argument("--threads", type=int, default=1,
                   help="torch CPU threads (0: torch's default). 1 is fastest on a small CPU, where torch and "
                        "the lavapipe rasteriser compete for cores")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    import torch

    from gma.avatar import Avatar
    from gma.core.errors import InputError
    from gma.data import read_sequence
    from gma.train.config import PoseRefineConfig
    from gma.train.evaluate import EVAL_SPLITS, evaluate_splits

    if args.threads:
        torch.set_num_threads(args.threads)
    avatar = Avatar.load(args.avatar)
    seq = read_sequence(args.sequence)
    out = Path(args.out) if args.out else Path(args.avatar).with_suffix(".eval")
    splits = [args.split]
    if args.split == "test" and not seq.split("test"):
        splits = list(EVAL_SPLITS)
    if not any(seq.split(s) for s in splits):  # else nothing would be scored, and the run would look fine
        have = sorted(k for k, v in seq.splits.items() if v)
        raise InputError(f"{seq.root}: no frames in split {args.split!r} (this sequence has: "
                         f"{', '.join(have) or 'no splits'}); choose one with --split")
    if args.refine_poses < 0:
        raise InputError(f"--refine-poses: expected a number of steps >= 0, got {args.refine_poses}")
    if args.refine_resolution != 0 and args.refine_resolution < 8:
        raise InputError(f"--refine-resolution: expected 0 (the avatar's) or >= 8, got {args.refine_resolution}")
    results = evaluate_splits(avatar, seq, splits, out, args.resolution, args.background, images=args.images,
                              refine_steps=args.refine_poses, refine_resolution=args.refine_resolution or None,
                              refine=PoseRefineConfig(bones=args.refine_bones),
                              refine_colour={"auto": None, "on": True, "off": False}[args.refine_colour])
    geometry = results["geometry"]
    if geometry is not None:  # synthetic sequences carry the true clothed mesh
        print("mesh layer vs ground-truth clothed mesh: " + ", ".join(f"{k} {v:.2f}" for k, v in geometry.items()))
    _seen_picture(avatar, out)
    print(f"wrote {out}")
    return 0


def _seen_picture(avatar, out) -> None:
    """``out/seen.png`` and a line on how much of the avatar was guessed, when the avatar records it."""
    from gma.body import load_body
    from gma.edit.unseen import guessed_share, seen_picture
    from gma.render.image_io import save_png

    if avatar.face_seen is None:
        return
    body = load_body(avatar.body_name)
    save_png(out / "seen.png", seen_picture(avatar, body))
    g = guessed_share(avatar, body)
    print(f"seen / guessed: {100 * g['area']:.0f} % of the body surface ({100 * g['faces']:.0f} % of the faces) "
          f"was never seen well by the training frames and was filled in ({out / 'seen.png'}: magenta)")
