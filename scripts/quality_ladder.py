#!/usr/bin/env python3
"""The viewer's frame qualities side by side (docs/viewer_quality.png): the full frame a settled view
shows, and each cheaper level the viewer draws while the view moves on a slow adapter, with the time
each takes where the script runs.

    python scripts/quality_ladder.py [--avatar out/demo/avatar.gma] [--size 400x600] [--out docs/viewer_quality.png]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--avatar", default=str(REPO / "out" / "demo" / "avatar.gma"),
                    help="a .gma (default: the demo's avatar; `make demo` makes it)")
    ap.add_argument("--size", default="300x450")
    ap.add_argument("--out", default=str(REPO / "docs" / "viewer_quality.png"))
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    import numpy as np
    import wgpu
    from PIL import Image, ImageDraw

    from gma.core.args import parse_image_size
    from gma.core.errors import MissingFileError
    from gma.core.report import run_reporting_errors
    from gma.gpu import get_context
    from gma.render.image_io import save_png
    from gma.view import FrameRenderer, OrbitCamera, Scene
    from gma.view.quality import LADDER
    from gma.view.renderer import read_texture
    from gma.view.source import avatar_source

    def run() -> int:
        if not Path(args.avatar).is_file():
            raise MissingFileError(f"{args.avatar} does not exist: run `make demo`, or pass --avatar")
        w, h = parse_image_size(args.size)
        ctx = get_context()
        src = avatar_source(ctx, args.avatar)
        scene = Scene(src)
        renderer = FrameRenderer(ctx)
        orbit = OrbitCamera.framing(*src.bounds(), up_axis=src.up_axis)
        orbit.orbit(-60, 0)  # three-quarter view: sides and front
        cam = orbit.camera(w, h)
        tex = ctx.device.create_texture(size=(w, h, 1), format="rgba8unorm",
                                        usage=wgpu.TextureUsage.RENDER_ATTACHMENT | wgpu.TextureUsage.COPY_SRC)
        renderer.render_image(scene, cam)  # pipelines, capacity
        tiles = []
        for q in LADDER:
            times = []
            for _ in range(args.repeats + 1):
                t0 = time.perf_counter()
                renderer.draw(scene, cam, tex.create_view(), "rgba8unorm", quality=q)
                img = read_texture(ctx, tex)  # waits for the frame
                times.append((time.perf_counter() - t0) * 1e3)
            ms = statistics.median(times[1:])
            tile = Image.fromarray(img[..., :3])
            draw = ImageDraw.Draw(tile)
            draw.rectangle((0, 0, w, 34), fill=(255, 255, 255))
            draw.text((6, 4), f"{q.label()}\n{ms:.0f} ms", fill=(0, 0, 0))
            tiles.append(np.asarray(tile))
            print(f"{q.label():<24} {ms:7.1f} ms ({src.surfels.count // q.stride} surfels, "
                  f"{q.image_size(w, h)[0]}x{q.image_size(w, h)[1]})")
        save_png(args.out, np.concatenate(tiles, 1))
        print(f"wrote {args.out} ({ctx.name})")
        return 0

    return run_reporting_errors(run, "quality_ladder")


if __name__ == "__main__":
    sys.exit(main())
