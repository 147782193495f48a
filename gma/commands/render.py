"""``gma render SOURCE -o OUT``: render frames or a video offscreen (no window) along a camera path while
playing a motion.

    gma render body:anny -o walk.mp4 --motion walk --orbit 1 --seconds 4 --size 640x480
    gma render splats.ply -o frames/ --orbit 0.5
    gma render body:anny -o still.gif --seconds 0 (a single frame)
    gma render me.gma -o still.png --seconds 0 --motion dance.npz --frame 40
    gma render me.gma -o dance.mp4 --motion dance.npz --orbit 0 (a motion from gma import motion)
"""

from __future__ import annotations

import argparse
import sys

import numpy as np

from gma.core.args import non_negative_float, non_negative_int, parse_image_size, positive_float, positive_int
from gma.core.errors import InputError

# A render longer than this is a typo (--seconds 1e6), not a request: an hour at 30 fps.
MAX_FRAMES = 108_000


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render an avatar, splat PLY or the body offscreen to MP4/GIF/PNGs")
    p.add_argument("source", help="a fitted avatar .gma, a splat .ply, or body:anny / body:smplx")
    p.add_argument("-o", "--out", required=True,
                   help="output: .mp4, .gif, .png (one frame: --seconds 0), or a directory for PNG frames")
    p.add_argument("--size", type=parse_image_size, default=(640, 480), help="image size, N or WxH (default 640x480)")
    p.add_argument("--motion", default=None, help="built-in motion (turn, walk, wave, expressions), a motion file "
                   "(gma import motion output, .bvh, AMASS/SMPL-X .npz) or a sequence's body.npz")
    p.add_argument("--frame", type=non_negative_int, default=0, help="start at this frame of --motion")
    p.add_argument("--orbit", type=float, default=1.0, help="turns of the camera around the subject")
    p.add_argument("--elevation", type=float, default=10.0, help="camera elevation in degrees")
    p.add_argument("--seconds", type=non_negative_float, default=4.0, help="duration (0: one frame)")
    p.add_argument("--fps", type=positive_float, default=30.0, help="frames per second")
    p.add_argument("--surfels", type=positive_int, default=50_000, help="placeholder surfels for body:* sources")
    p.add_argument("--background", default="1,1,1", help="background colour r,g,b in [0, 1]")
    p.add_argument("--force", action="store_true", help="overwrite OUT (a folder only if it holds recorded frames)")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gma.gpu import get_context
    from gma.view import CameraPath, OrbitCamera, Scene
    from gma.view.controls import BodyControls, load_motion
    from gma.view.record import Recorder, prepare_recording
    from gma.view.renderer import FrameRenderer
    from gma.view.source import load_source

    width, height = args.size
    frames = max(1, round(args.seconds * args.fps))
    if frames > MAX_FRAMES:
        raise InputError(f"--seconds {args.seconds:g} at --fps {args.fps:g} is {frames:,} frames; at most "
                         f"{MAX_FRAMES:,} (an hour at 30 fps) per render")
    background = parse_background(args.background)
    if str(args.out).lower().endswith(".png") and frames != 1:
        raise InputError(f"{args.out}: a .png holds one frame; add --seconds 0 (or write .gif/.mp4/a folder)")
    if args.frame and not args.motion:
        raise InputError("--frame needs --motion")
    prepare_recording(args.out, args.force)  # bad suffix, existing output: before loading anything
    ctx = get_context()
    ctx.check_image_size(width, height, "--size")
    source = load_source(ctx, args.source, args.surfels)
    scene = Scene(source)
    scene.options.background = background
    pose_at = None
    if args.motion:
        if getattr(source, "body", None) is None:
            raise ValueError(f"{args.source}: has no body, so --motion cannot animate it")
        controls = BodyControls(source)
        controls.set_motion(load_motion(args.motion, source.body))
        if args.frame >= len(controls.motion):
            raise InputError(f"--frame {args.frame}: the motion has {len(controls.motion)} frames")

        def pose_at(i: int) -> None:
            controls.scrub(args.frame + round(i * controls.motion.fps / args.fps))

        bounds = motion_bounds(source, pose_at, frames)
    else:
        bounds = source.bounds()
    start = OrbitCamera.framing(*bounds, up_axis=source.up_axis)
    start.elevation = args.elevation
    path = CameraPath.turntable(start, max(args.seconds, 1e-6), args.orbit)

    recorder = Recorder(FrameRenderer(ctx), scene, args.out, path, width, height, args.fps, frames, pose_at)
    try:
        out = recorder.run(lambda p: print(f"\rrendering {p:6.1%}", end="", file=sys.stderr))
    except BaseException:
        recorder.abort()
        raise
    print(f"\nwrote {out} ({frames} frames, {recorder.width}x{recorder.height})", file=sys.stderr)
    return 0


def motion_bounds(source, pose_at, frames: int, samples: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(min [3], max [3]) of the posed body over ``samples`` frames of the render, so the camera frames
    the motion as played (a motion file's root need not stay at the rest pose's place), first frame
    included; ends posed at the first frame."""
    lo, hi = [], []
    for i in sorted({round(k * (frames - 1) / max(samples - 1, 1)) for k in range(samples)}, reverse=True):
        pose_at(i)
        v = source.posed_vertices()
        lo.append(v.min(0))
        hi.append(v.max(0))
    return np.min(lo, 0), np.max(hi, 0)


def parse_background(text: str) -> tuple[float, float, float]:
    """``r,g,b`` with each value in [0, 1]."""
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) != 3 or not all(0.0 <= v <= 1.0 for v in values):
        raise InputError(f"--background must be r,g,b with values in [0, 1], got {text!r}")
    return values
