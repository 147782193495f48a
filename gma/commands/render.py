"""``gma render SOURCE -o OUT``: render frames or a video offscreen (no window) along a camera path while
playing a motion.

    gma render body:anny -o walk.mp4 --motion walk --orbit 1 --seconds 4 --size 640x480
    gma render splats.ply -o frames/ --orbit 0.5
    gma render body:anny -o still.gif --seconds 0 (a single frame)
"""

from __future__ import annotations

import argparse
import sys

from gma.core.args import parse_image_size


def register(subparsers) -> None:
    p = subparsers.add_parser("render", help="render an avatar, splat PLY or the body offscreen to MP4/GIF/PNGs")
    p.add_argument("source", help="a fitted avatar .gma, a splat .ply, or body:anny / body:smplx")
    p.add_argument("-o", "--out", required=True, help="output: .mp4, .gif, or a directory for PNG frames")
    p.add_argument("--size", type=parse_image_size, default=(640, 480), help="image size, N or WxH (default 640x480)")
    p.add_argument("--motion", default=None, help="built-in motion (turn, walk, wave, expressions) or body.npz")
    p.add_argument("--orbit", type=float, default=1.0, help="turns of the camera around the subject")
    p.add_argument("--elevation", type=float, default=10.0, help="camera elevation in degrees")
    p.add_argument("--seconds", type=float, default=4.0, help="duration (0: one frame)")
    p.add_argument("--fps", type=float, default=30.0, help="frames per second")
    p.add_argument("--surfels", type=int, default=50_000, help="placeholder surfels for body:* sources")
    p.add_argument("--background", default="1,1,1", help="background colour r,g,b in [0, 1]")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gma.gpu import get_context
    from gma.view import CameraPath, OrbitCamera, Scene
    from gma.view.controls import BodyControls, load_motion
    from gma.view.record import Recorder, output_kind
    from gma.view.renderer import FrameRenderer
    from gma.view.source import load_source

    width, height = args.size
    output_kind(args.out)  # fail on a bad suffix before loading anything
    try:
        background = tuple(float(v) for v in args.background.split(","))
        assert len(background) == 3
    except (ValueError, AssertionError):
        raise ValueError(f"--background must be r,g,b, got {args.background!r}") from None
    ctx = get_context()
    source = load_source(ctx, args.source, args.surfels)
    scene = Scene(source)
    scene.options.background = background
    start = OrbitCamera.framing(*source.bounds(), up_axis=source.up_axis)
    start.elevation = args.elevation
    frames = max(1, round(args.seconds * args.fps))
    path = CameraPath.turntable(start, max(args.seconds, 1e-6), args.orbit)
    pose_at = None
    if args.motion:
        if getattr(source, "body", None) is None:
            raise ValueError(f"{args.source}: has no body, so --motion cannot animate it")
        controls = BodyControls(source)
        controls.set_motion(load_motion(args.motion, source.body))

        def pose_at(i: int) -> None:
            controls.scrub(round(i * controls.motion.fps / args.fps))

    recorder = Recorder(FrameRenderer(ctx), scene, args.out, path, width, height, args.fps, frames, pose_at)
    try:
        out = recorder.run(lambda p: print(f"\rrendering {p:6.1%}", end="", file=sys.stderr))
    except BaseException:
        recorder.abort()
        raise
    print(f"\nwrote {out} ({frames} frames, {recorder.width}x{recorder.height})", file=sys.stderr)
    return 0
