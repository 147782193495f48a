"""Viewer frame rate while animating: the body with N placeholder surfels playing a built-in motion in a
real window (Xvfb is started when there is no DISPLAY), with the per-pass GPU breakdown from timestamp
queries (sampled every ``--sample-every`` frames; sampling is a sync point, so it is kept rare).

    python benchmarks/viewer_fps.py --size 800x600 --surfels 200000 --frames 40
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from viewer.display import ensure_display  # noqa: E402


def synced_breakdown(ctx, state, w: int, h: int, frames: int = 3) -> dict[str, float]:
    """Mean wall-clock ms of posing, projection + depth sort, binning + tile sort + rasterization, and the
    overlay/blit pass, each submitted separately and waited for (a benchmark-only sync per stage)."""
    import numpy as np
    import wgpu

    r, scene, src = state.renderer, state.scene, state.source
    rast = r.rasterizer
    cam = state.camera(w, h)
    target = ctx.device.create_texture(size=(w, h, 1), format="rgba8unorm",
                                       usage=wgpu.TextureUsage.RENDER_ATTACHMENT)
    probe = ctx.buffer(4, "probe")

    def wait():
        ctx.read(probe, np.uint32, 1)

    out = {"pose": 0.0, "project+depth sort": 0.0, "bin+sort+raster": 0.0, "blit+overlays": 0.0}
    for _ in range(frames):
        state.controls.scrub(state.controls.frame + 1)
        t0 = time.perf_counter()
        enc = ctx.device.create_command_encoder()
        src.encode_update(enc)
        ctx.submit(enc)
        wait()
        t1 = time.perf_counter()
        enc = ctx.device.create_command_encoder()
        cap = rast.isect_capacity_hint
        st = rast.project(enc, src.surfels, cam, cap)
        ctx.submit(enc)
        wait()
        t2 = time.perf_counter()
        enc = ctx.device.create_command_encoder()
        rast.bin_and_rasterize(enc, src.surfels, cam, st, cap, r._background, r._image_view)
        ctx.submit(enc)
        wait()
        t3 = time.perf_counter()
        scene.options.surfels = False  # the pass below: blit stand-in (clear) + overlays, no surfel render
        r.draw(scene, cam, target.create_view(), "rgba8unorm")
        scene.options.surfels = True
        wait()
        t4 = time.perf_counter()
        for k, a, b in (("pose", t0, t1), ("project+depth sort", t1, t2), ("bin+sort+raster", t2, t3),
                        ("blit+overlays", t3, t4)):
            out[k] += (b - a) * 1e3 / frames
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="800x600")
    ap.add_argument("--surfels", type=int, default=200_000)
    ap.add_argument("--motion", default="walk")
    ap.add_argument("--frames", type=int, default=20)
    ap.add_argument("--sample-every", type=int, default=5)
    args = ap.parse_args()
    xvfb = ensure_display("1280x1024x24")
    try:
        from gma.core.args import parse_image_size
        from gma.gpu import get_context
        from gma.view import BodySource
        from gma.view.timing import FrameStats
        from viewer.state import ViewerState
        from viewer.window import ViewerWindow

        w, h = parse_image_size(args.size)
        ctx = get_context()
        from gma.body import load_body

        source = BodySource.placeholder(ctx, load_body("anny"), args.surfels)
        state = ViewerState(ctx, source)
        state.play_motion(args.motion)
        win = ViewerWindow(state, w, h, panels=False)
        win.stats = FrameStats(ctx, every=args.sample_every, window=args.frames)
        for _ in range(5):  # warm-up: pipelines, capacity growth
            win.draw_frame()
        state.renderer.rasterizer.grow_capacity(state.renderer.last_state)
        samples: list[dict] = []
        t0 = time.perf_counter()
        frames_played = state.controls.frame
        for _ in range(args.frames):
            win.draw_frame()
            if win.stats.gpu_ms and win.stats.frame % args.sample_every == 1:
                samples.append(dict(win.stats.gpu_ms))
        ctx.read(state.renderer.last_state.stats, "u4", 1)  # wait for the last frame
        elapsed = time.perf_counter() - t0
        synced = synced_breakdown(ctx, state, w, h, frames=3)
        win.close()
        print(f"device: {ctx.name}")
        print(f"{args.surfels} surfels, {w}x{h}, motion {args.motion!r} playing "
              f"(frame {frames_played} -> {state.controls.frame}), {args.frames} frames")
        print(f"FPS {args.frames / elapsed:.2f} ({1e3 * elapsed / args.frames:.1f} ms/frame, wall clock, "
              f"incl. {len(samples)} timestamp-sampled frames)")
        if samples:
            keys = list(samples[0])
            print("GPU ms per pass (mean over sampled frames):")
            for k in keys:
                vals = [s.get(k, 0.0) for s in samples]
                print(f"  {k:>10s} {sum(vals) / len(vals):8.2f}")
            print(f"  {'total':>10s} {sum(sum(s.values()) for s in samples) / len(samples):8.2f}")
        print("wall-clock ms per stage, each submitted alone and waited for (reliable where timestamps are not,")
        print("e.g. lavapipe, whose timestamps do not wait for the compute work):")
        for k, v in synced.items():
            print(f"  {k:>18s} {v:8.1f}")
    finally:
        if xvfb is not None:
            xvfb.terminate()


if __name__ == "__main__":
    main()
