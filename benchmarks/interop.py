"""Figures for issue 14 (interop): export time and sizes, splat round-trip PSNR, retargeting angle errors.

    python3 benchmarks/interop.py [avatar.gma] [--size 256] [--quick] [--out DIR]

Without an avatar, a fresh default-config avatar with randomised decoders stands in (varied colours and
scales). Prints one line per figure. The exported files and renders go to a temporary directory that is
removed at the end, or are kept in ``--out DIR`` (a new or empty directory).
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
import torch

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))  # this checkout's gma, whichever is installed


def _tests_module():
    spec = importlib.util.spec_from_file_location("tmf", REPO / "tests" / "test_motion_files.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _cli(*args: str) -> float:
    start = time.perf_counter()
    subprocess.run([sys.executable, "-m", "gma.cli", *args], check=True, cwd=REPO, stderr=subprocess.DEVNULL)
    return time.perf_counter() - start


def foot_report(body, motion) -> str:
    """Root height, how far the lowest foot joint is above the floor (the rest pose's lowest foot joint)
    and how fast it slides while it is within 2 cm of the floor (foot skate), over a motion."""
    from gma.body.retarget import rest_heads

    feet = [body.bone_names.index(n) for n in ("foot.L", "foot.R", "toe3-1.L", "toe3-1.R")]
    heads = torch.from_numpy(rest_heads(body, motion.shape)).float()[feet]

    def posed(pose):
        with torch.no_grad():
            tr = body.bone_transforms({"pose": pose, "shape": motion.shape})[..., feet, :, :]
        return ((tr[..., :3, :3] @ heads[:, :, None])[..., 0] + tr[..., :3, 3]).numpy()

    floor = posed(body.canonical_pose()[None])[0, :, 2].min()
    p = posed(motion.pose)  # [T, F, 3]
    low = p[..., 2].min(1) - floor
    idx = p[..., 2].argmin(1)
    lowest = p[np.arange(len(p)), idx]
    same = idx[1:] == idx[:-1]
    planted = same & (low[1:] < 0.02) & (low[:-1] < 0.02)
    slide = np.linalg.norm(lowest[1:, :2] - lowest[:-1, :2], axis=1) * motion.fps
    root = motion.pose[:, 0, 2, 3].numpy()
    skate = f"{np.median(slide[planted]):.3f} m/s median over {planted.sum()} planted steps" if planted.any() \
        else "no planted frames"
    return (f"{len(motion)} frames at {motion.fps:g} fps: root height {root.min():+.3f}..{root.max():+.3f} m; "
            f"lowest foot joint {low.min() * 100:.1f}..{low.max() * 100:.1f} cm above the floor; foot skate {skate}")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("avatar", nargs="?")
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--motion", action="append", default=[], help="also report feet and root of this motion file")
    ap.add_argument("--quick", action="store_true",
                    help="one splat and one mesh export, one round trip (each is a whole command, "
                         "seconds each; the test suite's smoke run)")
    ap.add_argument("--out", help="keep the exports and renders in this directory (new or empty)")
    args = ap.parse_args()
    if not 16 <= args.size <= 4096:
        ap.error(f"--size {args.size}: must lie in 16..4096 (pixels of the round trip's square renders)")
    if args.avatar is not None and not Path(args.avatar).is_file():
        ap.error(f"{args.avatar}: avatar file not found")
    if args.out is None:
        with tempfile.TemporaryDirectory(prefix="gma-interop-") as tmp:
            report(args, Path(tmp))
        return
    out = Path(args.out)
    if out.exists() and (not out.is_dir() or any(out.iterdir())):
        ap.error(f"{out}: exists and is not an empty directory (nothing there is overwritten)")
    out.mkdir(parents=True, exist_ok=True)
    report(args, out)
    print(f"outputs in {out}")


def report(args, tmp: Path) -> None:
    """Every figure, with the intermediate files in ``tmp``."""
    from gma.avatar import Avatar, AvatarConfig
    from gma.avatar.gpu import AvatarRenderer
    from gma.body import load_body
    from gma.body.motion_files import save_motion
    from gma.body.motions import motion
    from gma.core.camera import Camera
    from gma.gpu import get_context
    from gma.render.image_io import save_png

    body = load_body("anny")
    path = args.avatar
    if path is None:
        av = Avatar.create(AvatarConfig(), body, seed=1)
        g = torch.Generator().manual_seed(0)
        with torch.no_grad():
            for p in av.model.parameters():
                p.add_(0.3 * torch.randn(p.shape, generator=g))
        path = str(av.save(tmp / "avatar.gma"))
    av = Avatar.load(path, body)
    print(f"avatar {path}: {len(av.decode().binding):,} surfels, {os.path.getsize(path) / 1e6:.1f} MB; "
          f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs")
    walk = motion("walk", 16, body)
    save_motion(tmp / "walk.npz", walk)
    exports = [("a.ply", []), ("a2.ply", ["--format", "2dgs"]), ("a3.ply", ["--sh-degree", "3"]),
               ("m.glb", []), ("m.obj", []), ("mt.glb", ["--texture", "1024"])]
    if args.quick:  # one splat, one mesh
        exports = [e for e in exports if e[0] in ("a.ply", "m.glb")]
    for out, extra in exports:
        t = _cli("export", path, str(tmp / out), *extra)
        size = (tmp / out).stat().st_size / 1e6
        print(f"export {out:7s} {' '.join(extra):16s} {t:5.1f} s (whole command) {size:6.2f} MB")
    ctx = get_context()
    renderer = AvatarRenderer(ctx, av, body)
    cam = Camera.look_at((0.0, -3.2, 0.0), (0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0), fov_y_deg=40.0,
                         width=args.size, height=args.size)
    (tmp / "cam.json").write_text(json.dumps(cam.to_json()))
    views = [("canonical", [], {}),
             ("walk frame 7", ["--motion", str(tmp / "walk.npz"), "--frame", "7"],
              {"pose": walk.pose[7], "expression": walk.expression[7]})]
    for label, extra, params in views[1:] if args.quick else views:
        own = renderer.render(params, cam, background=(0.0, 0.0, 0.0))
        save_png(tmp / "own.png", own)
        for layout in ("2dgs",) if args.quick else ("3dgs", "2dgs"):
            _cli("export", path, str(tmp / "rt.ply"), "--format", layout, "--force", *extra)
            _cli("render-ply", str(tmp / "rt.ply"), "--camera", str(tmp / "cam.json"), "-o", str(tmp / "rt.png"),
                 "--force")  # one file, rewritten for each export
            a = iio.imread(tmp / "own.png")[..., :3] / 255.0
            b = iio.imread(tmp / "rt.png")[..., :3] / 255.0
            psnr = 10 * np.log10(1 / max(np.mean((a - b) ** 2), 1e-12))
            print(f"round trip {label:13s} {layout}: PSNR {psnr:.1f} dB at {args.size}x{args.size}")
    tm = _tests_module()
    tm.write_bvh(tmp / "m.bvh")
    err = tm.bvh_direction_errors(body, tmp / "m.bvh")
    print(f"BVH retarget limb direction error (8 limbs x 3 frames): mean {err.mean():.2f} deg, max {err.max():.2f} deg")
    tm.write_amass(tmp / "a.npz", tm.AMASS_POSES)
    err = tm.amass_direction_errors(body, tmp / "a.npz", tm.amass_expected(body))
    print(f"AMASS/SMPL-X retarget limb direction error (4 posed limbs): mean {err.mean():.2f} deg, "
          f"max {err.max():.2f} deg")
    from gma.body.motion_files import load_motion_file

    for label, m in [("test BVH", load_motion_file(tmp / "m.bvh", body)),
                     ("built-in walk", walk)] + [(f, load_motion_file(f, body)) for f in args.motion]:
        print(f"{label}: {foot_report(body, m)}")


if __name__ == "__main__":
    main()
