"""``gma demo``: the main job on the built-in default. For now it renders the built-in avatar-like surfel
scene from a few views (colour, normals, depth) and times the renderer; the avatar pipeline (synthesise,
fit, evaluate, animate) replaces this as it lands."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("demo", help="run the built-in demo", description=__doc__)
    p.add_argument("--out", default="out/demo", help="output folder")
    p.add_argument("--surfels", type=int, default=200_000, help="surfels in the built-in scene")
    p.add_argument("--size", type=int, default=512, help="image width and height")
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    import torch

    from gma.gpu import get_context
    from gma.render import rasterize
    from gma.render.image_io import save_png
    from gma.render.scenes import avatar_camera, avatar_like_scene

    out = Path(args.out)
    ctx = get_context()
    print(f"[demo] adapter: {ctx.name}")
    scene = {k: torch.from_numpy(v) for k, v in avatar_like_scene(args.surfels).items()}
    tiles = []
    for azimuth in (0, 60, 180):
        cam = avatar_camera(args.size, args.size, azimuth)
        view, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)
        t0 = time.perf_counter()
        r = rasterize(scene["means"], scene["quats"], scene["scales"], scene["opacities"], scene["colors"],
                      view, K, cam.width, cam.height, background=torch.ones(3), ctx=ctx)
        ms = (time.perf_counter() - t0) * 1e3
        normal = (0.5 - 0.5 * r.normal.numpy() / np.maximum(r.alpha.numpy(), 1e-6)) * r.alpha.numpy() + (
            1 - r.alpha.numpy())
        tiles.append(np.concatenate([r.color.numpy(), normal], 1))
        print(f"[demo] view {azimuth:3d} deg: {args.surfels} surfels at {args.size}x{args.size} in {ms:.0f} ms")
    path = save_png(out / "surfel_scene.png", np.concatenate(tiles, 0))
    print(f"[demo] wrote {path}")
    return 0
