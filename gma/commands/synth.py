"""``gma synth OUT --seed N``: a synthetic clothed person with exact ground truth (images, masks,
cameras, body parameters, the textured mesh), for tests, the demo and measuring fits."""

from __future__ import annotations

import argparse

from gma.core.args import non_negative_int, parse_image_size, positive_int


def _run(args: argparse.Namespace) -> int:
    import time

    from gma.data.sequence import prepare_sequence_output
    from gma.synth.generate import SynthConfig, synthesize

    prepare_sequence_output(args.out, args.force)  # in a second, before the body model loads

    w, h = args.size
    cfg = SynthConfig(
        preset=args.preset,
        seed=args.seed,
        width=w,
        height=h,
        train_frames=args.frames,
        test_pose_frames=args.test_pose_frames,
        test_view_frames=args.test_view_frames,
        supersample=args.supersample,
        texture_size=args.texture_size,
    )
    t0 = time.perf_counter()
    seq = synthesize(args.out, cfg, overwrite=args.force)
    dt = time.perf_counter() - t0
    counts = ", ".join(f"{k} {len(v)}" for k, v in seq.splits.items())
    print(f"wrote {seq.root}: {len(seq)} frames at {w}x{h} ({counts}) in {dt:.1f} s")
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser("synth", help="generate a synthetic ground-truth sequence", description=__doc__)
    p.add_argument("out", help="output sequence directory (written atomically)")
    p.add_argument(
        "--seed", type=int, default=0, help="person, clothes, test poses and cameras follow from it"
    )
    p.add_argument(
        "--preset",
        choices=("turn", "motion"),
        default="turn",
        help="turn: slow A-pose turn before a static camera (PeopleSnapshot-like); "
        "motion: varied motion (X-Humans-like)",
    )
    p.add_argument("--size", type=parse_image_size, default=(512, 512), help="image size, N or WxH (default 512)")
    p.add_argument("--frames", type=positive_int, default=60, help="training frames")
    p.add_argument("--test-pose-frames", type=non_negative_int, default=10, help="held-out novel-pose frames")
    p.add_argument("--test-view-frames", type=non_negative_int, default=10, help="held-out novel-view frames")
    p.add_argument("--supersample", type=positive_int, default=3, help="anti-aliasing factor per axis")
    p.add_argument("--texture-size", type=positive_int, default=2048, help="ground-truth texture resolution")
    p.add_argument("--force", action="store_true", help="replace OUT if it is a sequence (never another folder)")
    p.set_defaults(func=_run)
