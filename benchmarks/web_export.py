"""Figures of ``gma export avatar.gma page.html``: the page's size, how closely a frame of it matches
``gma render`` of the same frame and camera (PSNR inside the person's box, 512²), and the FPS it plays at
in headless Chromium (software WebGL, 640²).

    python benchmarks/web_export.py                        # a quick-preset-sized avatar, the walk
    python benchmarks/web_export.py --avatar me.gma --screenshot docs/web_export.png

Without ``--avatar`` the avatar has the quick preset's surfels (54,840) and random decoder weights: its
colours vary from surfel to surfel, which a fitted avatar's do not, so it is the harder case for
fidelity. Needs ``web/dist`` (scripts/install.sh), Debian's chromium and playwright.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import machine  # noqa: E402
from web_browser import browser, capture, missing_browser, open_page, page_fps  # noqa: E402

FIDELITY_SIZE = (512, 512)
FPS_SIZE = (640, 640)
FRAMES = (0, 30, 75)  # of the 4-second walk at 30 fps


def quick_avatar(path: Path) -> Path:
    """A quick-preset-sized avatar with random decoder weights (varied colours, scales and offsets)."""
    from gma.avatar import Avatar, AvatarConfig
    from gma.body import load_body
    from gma.train.config import PRESETS

    avatar = Avatar.create(AvatarConfig(**PRESETS["quick"]["avatar"]), load_body("anny"), seed=1)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in avatar.model.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g))
    avatar.save(path)
    return path


def export(avatar: Path, out: Path, size: tuple[int, int], motion: str) -> float:
    from gma.cli import main as gma_main

    start = time.perf_counter()
    code = gma_main(["export", str(avatar), str(out), "--motion", motion, "--size", f"{size[0]}x{size[1]}",
                     "--force"])
    if code != 0:
        raise SystemExit(f"gma export failed ({code})")
    return time.perf_counter() - start


def gma_frames(avatar: Path, motion: str, frames: tuple[int, ...], size: tuple[int, int]) -> list[np.ndarray]:
    """[H, W, 3] uint8 `gma render` images of ``frames`` with the page's starting camera."""
    from gma.avatar.avatar import Avatar
    from gma.body import load_body
    from gma.commands._export_web import page_camera
    from gma.gpu import get_context
    from gma.view import FrameRenderer, Scene, load_source
    from gma.view.controls import BodyControls, load_motion

    ctx = get_context()
    source = load_source(ctx, str(avatar))
    scene = Scene(source)
    scene.options.background = (1.0, 1.0, 1.0)
    controls = BodyControls(source)
    controls.set_motion(load_motion(motion, source.body))
    orbit, _ = page_camera(Avatar.load(avatar), load_body("anny"), controls.motion)
    renderer = FrameRenderer(ctx)
    images = []
    for f in frames:
        controls.scrub(f)
        images.append(renderer.render_image(scene, orbit.camera(*size))[..., :3])
    return images


def box_psnr(page: np.ndarray, reference: np.ndarray) -> float:
    """PSNR (dB) inside the person's box: where the reference differs from the white background."""
    from gma.train.metrics import box_metrics

    a, b = (torch.from_numpy(x.astype(np.float32) / 255) for x in (page, reference))
    mask = ((b < 0.98).any(-1, keepdim=True)).float()
    return box_metrics(a, b, mask)["psnr_bbox"]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--avatar", type=Path, default=None, help="a fitted avatar (default: quick-preset-sized)")
    ap.add_argument("--motion", default="walk", help="the motion (default walk, 4 s)")
    ap.add_argument("--screenshot", type=Path, default=None, help="save the page's 640² frame here (docs)")
    ap.add_argument("--pairs", type=Path, default=None, help="save page | gma render pairs here (a folder)")
    args = ap.parse_args(argv)
    why = missing_browser()
    if why:
        print(f"web_export: {why}", file=sys.stderr)
        return 2
    import imageio.v3 as iio

    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        avatar = args.avatar or quick_avatar(tmp / "random_quick.gma")
        page512, page640 = tmp / "a512.html", tmp / "a640.html"
        seconds = export(avatar, page512, FIDELITY_SIZE, args.motion)
        export(avatar, page640, FPS_SIZE, args.motion)
        references = gma_frames(avatar, args.motion, FRAMES, FIDELITY_SIZE)
        print(f"machine: {machine()}")
        print(f"page: {page512.stat().st_size / 1e6:.2f} MB ({args.motion}, {avatar.name}), export {seconds:.1f} s")
        with browser() as b:
            for frame, reference in zip(FRAMES, references):
                tab = open_page(b, page512, FIDELITY_SIZE, f"#t={frame / 30:.4f}")
                tab.wait_for_timeout(500)
                shot = capture(tab)
                tab.close()
                print(f"frame {frame:3d}: PSNR in the person's box {box_psnr(shot, reference):.2f} dB (512²)")
                if args.pairs:
                    args.pairs.mkdir(parents=True, exist_ok=True)
                    iio.imwrite(args.pairs / f"pair_{frame:03d}.png", np.concatenate([shot, reference], 1))
            tab = open_page(b, page640, FPS_SIZE)
            print(f"playing at 640²: {page_fps(tab):.2f} FPS (headless Chromium, SwiftShader WebGL)")
            tab.evaluate("window.gmaPlayer.playing = false")
            print(f"paused at 640²: {page_fps(tab):.2f} FPS")
            if args.screenshot:
                tab.evaluate("window.gmaPlayer.time = 1.0")
                tab.wait_for_timeout(2000)
                tab.screenshot(path=str(args.screenshot), timeout=120_000)
                print(f"wrote {args.screenshot}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
