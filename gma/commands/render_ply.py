"""``gma render-ply scene.ply --camera cam.json -o out.png``: render a standard Gaussian-splat PLY."""

from __future__ import annotations

import argparse

import numpy as np

from gma.core.args import parse_image_size
from gma.core.outputs import prepare_output_file


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("render-ply", help="render a Gaussian-splat PLY (INRIA layout) to a PNG",
                       description="Render a 3DGS/2DGS splat PLY with the WGSL surfel renderer. 3D Gaussians "
                                   "are reduced to surfels by dropping their smallest scale.")
    p.add_argument("ply", help="splat file (x, y, z, scale_*, rot_0..3, opacity logit, f_dc_0..2)")
    p.add_argument("--camera", help="camera JSON {width, height, K (3x3), w2c (4x4)}; default: an automatic "
                                    "view that frames the whole scene")
    p.add_argument("-o", "--output", required=True, help="output PNG")
    p.add_argument("--size", type=parse_image_size, default=(800, 800),
                   help="image size for the automatic camera")
    p.add_argument("--background", type=float, nargs=3, default=(0.0, 0.0, 0.0), metavar=("R", "G", "B"))
    p.add_argument("--depth", help="also write a normalised depth PNG here")
    p.add_argument("--force", action="store_true", help="overwrite existing output files")
    p.set_defaults(func=run)


def framing_camera(means: np.ndarray, width: int, height: int):
    """A camera looking at the centre of ``means`` along +z from far enough to see them all."""
    from gma.core.camera import Camera

    lo, hi = np.percentile(means, 1, axis=0), np.percentile(means, 99, axis=0)
    centre = (lo + hi) / 2
    radius = float(np.linalg.norm(hi - lo)) / 2 or 1.0
    eye = centre - np.array([0.0, 0.0, 2.5 * radius])
    return Camera.look_at(eye, centre, up=(0.0, -1.0, 0.0), fov_y_deg=45.0, width=width, height=height)


def run(args: argparse.Namespace) -> int:
    import torch

    from gma.core.camera import Camera
    from gma.render import rasterize
    from gma.render.image_io import save_png
    from gma.render.ply import load_splat_ply

    prepare_output_file(args.output, args.force, "image")
    if args.depth:
        prepare_output_file(args.depth, args.force, "depth image")
    splats = load_splat_ply(args.ply)
    cam = Camera.load(args.camera) if args.camera else framing_camera(splats["means"], *args.size)
    t = {k: torch.from_numpy(v) for k, v in splats.items()}
    out = rasterize(t["means"], t["quats"], t["scales"], t["opacities"], t["colors"],
                    torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height,
                    background=torch.tensor(args.background, dtype=torch.float32))
    save_png(args.output, out.color.numpy())
    if args.depth:
        d = out.depth.numpy() / np.maximum(out.alpha.numpy(), 1e-6)
        valid = out.alpha.numpy() > 0.5
        lo, hi = (np.percentile(d[valid], [1, 99]) if valid.any() else (0.0, 1.0))
        save_png(args.depth, np.where(valid, 1 - (d - lo) / max(hi - lo, 1e-6), 0.0))
    print(f"rendered {len(splats['means'])} surfels at {cam.width}x{cam.height} -> {args.output}")
    return 0
