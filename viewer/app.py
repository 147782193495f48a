"""``gma-viewer`` / ``gma view``: open a surfel source in the real-time window."""

from __future__ import annotations

import argparse
import sys

from gma.core.args import non_negative_int, parse_image_size, positive_float, positive_int
from gma.core.outputs import prepare_output_file
from gma.core.report import run_reporting_errors

__all__ = ["add_arguments", "main", "run"]


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", nargs="?", default="body:anny",
                   help="a fitted avatar .gma, a splat .ply, or body:anny / body:smplx (placeholder surfels)")
    p.add_argument("--surfels", type=positive_int, default=50_000, help="placeholder surfels for body:* sources")
    p.add_argument("--size", type=parse_image_size, default=(800, 600), help="window size, N or WxH")
    p.add_argument("--motion", default=None, help="built-in motion (turn, walk, wave, expressions) or body.npz")
    p.add_argument("--sequence", default=None, help="sequence folder: its cameras become presets, its poses a motion")
    p.add_argument("--no-panels", action="store_true", help="no Dear ImGui panels (mouse and keys only)")
    p.add_argument("--target-fps", type=positive_float, default=12.0,
                   help="while the view moves, draw cheaper frames (fewer surfels, smaller image) to keep this rate; "
                        "a settled view is always drawn at full quality")
    p.add_argument("--full-quality", action="store_true", help="draw every frame at full quality, however slow")
    p.add_argument("--frames", type=non_negative_int, default=0,
                   help="draw this many frames and exit (0: until closed)")
    p.add_argument("--screenshot", default=None, help="with --frames: save the last frame as PNG")
    p.add_argument("--force", action="store_true", help="overwrite an existing --screenshot file")



def run(args: argparse.Namespace) -> int:
    import torch

    from gma.gpu import get_context
    from gma.view import load_source
    from gma.view.presets import sequence_cameras
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    # One intra-op thread: the edit solves run beside lavapipe's (or the driver's) threads and the frame
    # loop, and more OpenMP threads than free cores make every solve wait on the busiest of them.
    torch.set_num_threads(1)
    width, height = args.size
    ctx = get_context()
    ctx.check_image_size(width, height, "--size")  # before loading anything
    if args.screenshot:
        prepare_output_file(args.screenshot, args.force, "screenshot")
    source = load_source(ctx, args.source, args.surfels)
    presets = sequence_cameras(args.sequence) if args.sequence else []
    state = ViewerState(ctx, source, presets)
    motion = args.motion or (args.sequence if args.sequence and state.controls is not None else None)
    if motion:
        state.play_motion(motion)
    window = ViewerWindow(state, width, height, panels=not args.no_panels, target_fps=args.target_fps,
                          adaptive=not args.full_quality)
    if args.frames <= 0:
        window.run()
        return 0
    try:
        for _ in range(args.frames - 1):
            window.draw_frame()
        image = window.screenshot()
        if args.screenshot:
            import imageio.v3 as iio

            iio.imwrite(args.screenshot, image[..., :3])
        print(window.stats.summary())
    finally:
        window.close()
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="gma-viewer", description="GMA real-time viewer")
    add_arguments(parser)
    parser.add_argument("--debug", action="store_true", help="show the traceback of every error")
    args = parser.parse_args(argv)
    return run_reporting_errors(lambda: run(args), "gma-viewer", args.debug)

if __name__ == "__main__":
    sys.exit(main())
