"""Viewer frame rates in a real window (Xvfb is started when there is no DISPLAY), as a user meets them
(issue 15): for each source, frames per second

- ``full``: every frame at full quality while a motion plays (the viewer before adaptive quality);
- ``orbit``: the camera turning a little every frame, motion paused, adaptive quality;
- ``play``: a built-in motion playing, adaptive quality;
- ``still``: the view settled: the one full frame it draws, then the rate of frames that show it again;

with the quality levels the governor chose, and whether the settled frame is byte-identical to an
offscreen full-quality render of the same view. Sources: an avatar of the full preset's size (k = 32,
N_k = 4: 109,680 surfels; a fresh, unfitted one) and the body with N placeholder surfels.

    python benchmarks/viewer_fps.py [--size 800x600] [--surfels 200000] [--frames 30]
"""

from __future__ import annotations

import argparse
import collections
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402

from viewer.display import ensure_display  # noqa: E402


def wait_gpu(ctx, probe) -> None:
    ctx.read(probe, "u4", 1)


def run_frames(win, frames: int, step=None) -> tuple[float, collections.Counter]:
    """FPS over ``frames`` frames (GPU work waited for at the end), calling ``step()`` before each, and the
    quality labels drawn."""
    labels: collections.Counter = collections.Counter()
    ctx = win.ctx
    probe = ctx.buffer(4, "bench.probe")
    wait_gpu(ctx, probe)
    t0 = time.perf_counter()
    for _ in range(frames):
        if step:
            step()
        win.draw_frame()
        labels["reused" if win.last_quality is None else win.last_quality.label()] += 1
    wait_gpu(ctx, probe)
    return frames / (time.perf_counter() - t0), labels


def measure(name: str, state, w: int, h: int, frames: int, motion: str) -> dict:
    import numpy as np

    from viewer.window import ViewerWindow

    out: dict = {"source": name, "surfels": state.source.surfels.count}
    ctl = state.controls
    # 1. Full quality every frame, playing (what the viewer did before).
    win = ViewerWindow(state, w, h, panels=False, adaptive=False)
    state.play_motion(motion)
    run_frames(win, 3)
    state.renderer.rasterizer.grow_capacity(state.renderer.last_state)
    out["full"], _ = run_frames(win, frames)
    win.close()

    win = ViewerWindow(state, w, h, panels=False)
    # 2. Orbit, paused: the governor settles within a few frames (warm-up), then the measured run.
    ctl.playing = False
    run_frames(win, 8, lambda: state.orbit_by(6.0, 0.0))
    out["orbit"], out["orbit_levels"] = run_frames(win, frames, lambda: state.orbit_by(6.0, 0.0))
    # 3. Playing.
    ctl.playing = True
    run_frames(win, 8)
    out["play"], out["play_levels"] = run_frames(win, frames)
    # 4. Settled: the full frame, then frames that show it again.
    ctl.playing = False
    t0 = time.perf_counter()
    win.draw_frame()
    win.draw_frame()  # the first settled frame refines; this one is drawn full if the first was not
    probe = state.ctx.buffer(4, "bench.probe")
    wait_gpu(state.ctx, probe)
    out["settle_ms"] = (time.perf_counter() - t0) * 1e3
    out["still"], out["still_levels"] = run_frames(win, frames)
    shot = win.screenshot()[..., :3]
    ref = state.renderer.render_image(state.scene, state.camera(w, h))[..., :3]
    out["still_identical"] = bool(np.array_equal(shot, ref))
    out["still_max_diff"] = int(np.abs(shot.astype(int) - ref.astype(int)).max())
    win.close()
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="800x600")
    ap.add_argument("--surfels", type=int, default=200_000, help="placeholder surfels of the body source")
    ap.add_argument("--fine-per-face", type=int, default=4, help="N_k of the avatar source (4: full preset)")
    ap.add_argument("--motion", default="walk")
    ap.add_argument("--frames", type=int, default=30)
    args = ap.parse_args()
    xvfb = ensure_display("1280x1024x24")
    try:
        import torch

        from gma.avatar import Avatar
        from gma.avatar.config import AvatarConfig
        from gma.body import load_body
        from gma.core.args import parse_image_size
        from gma.gpu import get_context
        from gma.view import BodySource
        from gma.view.source import avatar_source
        from viewer.state import ViewerState

        torch.set_num_threads(1)  # as the viewer does (viewer/app.py)
        w, h = parse_image_size(args.size)
        ctx = get_context()
        body = load_body("anny")
        print(f"device: {ctx.name}; {machine()}; {w}x{h}, {args.frames} frames per run")
        rows = []
        with tempfile.TemporaryDirectory() as tmp:
            path = Path(tmp) / "avatar.gma"
            Avatar.create(AvatarConfig(fine_per_face=args.fine_per_face), body).save(path)
            rows.append(measure("avatar", ViewerState(ctx, avatar_source(ctx, path)), w, h, args.frames,
                                args.motion))
        rows.append(measure("body", ViewerState(ctx, BodySource.placeholder(ctx, body, args.surfels)), w, h,
                            args.frames, args.motion))
        print(f"{'source':<8} {'surfels':>8} {'full FPS':>9} {'orbit FPS':>10} {'play FPS':>9} {'settle ms':>10} "
              f"{'still FPS':>10} identical")
        for r in rows:
            print(f"{r['source']:<8} {r['surfels']:>8} {r['full']:9.2f} {r['orbit']:10.2f} {r['play']:9.2f} "
                  f"{r['settle_ms']:10.0f} {r['still']:10.1f} {r['still_identical']} (max diff {r['still_max_diff']})")
        for r in rows:
            for k in ("orbit_levels", "play_levels", "still_levels"):
                levels = ", ".join(f"{lab} x{n}" for lab, n in r[k].most_common())
                print(f"  {r['source']} {k.split('_')[0]}: {levels}")
        print(f"load after: {machine()}; median of orbit/play FPS: "
              f"{statistics.median([r[k] for r in rows for k in ('orbit', 'play')]):.2f}")
    finally:
        if xvfb is not None:
            xvfb.terminate()


if __name__ == "__main__":
    main()
