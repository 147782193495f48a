"""Time and disk size of ``gma synth`` for the default sequence (512×512, 60 + 10 + 10 frames), and an
optional contact sheet of a few frames.

    python benchmarks/synth.py [--size 512] [--seed 0] [--preset turn] \
        [--contact-sheet docs/synth_contact_sheet.png]

Prints the one-off setup (body model, dressing, texture bake), the rendering rate, the end-to-end frames
per second of generation and the size of each part of the output.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from gma.core.args import positive_int  # noqa: E402


def _du(path: Path) -> int:
    return (
        sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
        if path.is_dir()
        else path.stat().st_size
    )


def contact_sheet(seq_dir: Path, out: Path, tile: int = 256) -> None:
    """Four training frames, two novel poses, two novel views and the texture, in a 3×3 grid."""
    import imageio.v3 as iio
    from PIL import Image

    from gma.data import read_sequence

    seq = read_sequence(seq_dir)
    train, pose, view = seq.split("train"), seq.split("test_pose"), seq.split("test_view")
    picks = [train[int(k * len(train) / 4)] for k in range(4)] + pose[:2] + view[:2]
    tiles = [
        np.asarray(Image.fromarray(seq.image(i)).resize((tile, tile), Image.Resampling.LANCZOS))
        for i in picks
    ]
    tex = iio.imread(seq_dir / "gt_texture.png")
    tiles.append(np.asarray(Image.fromarray(tex).resize((tile, tile), Image.Resampling.LANCZOS)))
    rows = [np.concatenate(tiles[r * 3 : (r + 1) * 3], axis=1) for r in range(3)]
    out.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(out, np.concatenate(rows, axis=0), optimize=True)
    print(f"contact sheet: {out} (4 training frames, 2 novel poses, 2 novel views, then the texture)")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--size", type=int, default=512)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--preset", default="turn")
    ap.add_argument("--contact-sheet", type=Path, default=None)
    ap.add_argument("--train-frames", type=positive_int, default=60, help="training frames (then 10 + 10 held out)")
    ap.add_argument("--texture-size", type=positive_int, default=2048, help="ground-truth texture resolution")
    args = ap.parse_args()

    from gma.body import load_body
    from gma.gpu import get_context
    from gma.synth.generate import SynthConfig, synthesize
    from gma.synth.mesh_raster import MeshRasterizer
    from gma.synth.person import make_person

    t = time.perf_counter()
    ctx = get_context()
    body = load_body("anny")
    t_init = time.perf_counter() - t
    cfg = SynthConfig(preset=args.preset, seed=args.seed, width=args.size, height=args.size,
                      train_frames=args.train_frames, texture_size=args.texture_size)
    n = cfg.train_frames + cfg.test_pose_frames + cfg.test_view_frames
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "seq"
        t = time.perf_counter()
        synthesize(out, cfg, ctx=ctx, body=body, progress=False)
        total = time.perf_counter() - t

        # Break the total down: dressing + texture, then rendering alone.
        t = time.perf_counter()
        person = make_person(cfg.seed, cfg.texture_size, body)
        t_person = time.perf_counter() - t
        raster = MeshRasterizer(ctx, person.mesh, cfg.width, cfg.height, supersample=cfg.supersample)
        from gma.data import read_sequence

        seq = read_sequence(out)
        posed = np.load(out / "gt_mesh.npz")["posed_vertices"]
        raster.render(posed[0], *seq.cameras.frame(0))  # warm-up (pipeline creation)
        t = time.perf_counter()
        for i in range(n):
            raster.render(posed[i], *seq.cameras.frame(i))
        t_render = time.perf_counter() - t

        print(f"device: {ctx.name}")
        print(
            f"synth {args.preset} seed {args.seed}: {n} frames at {cfg.width}x{cfg.height}, "
            f"supersample {cfg.supersample}, texture {cfg.texture_size}^2"
        )
        print(f"  process setup (GPU context + Anny body, once): {t_init:6.2f} s")
        print(f"  synthesize() end to end:                      {total:6.2f} s  = {n / total:5.2f} frames/s")
        print(f"    of which person (dress + texture bake):     {t_person:6.2f} s")
        print(
            f"    rendering + readback alone:                 {t_render:6.2f} s  = {n / t_render:5.2f} fps"
        )
        sizes = {
            name: _du(out / name)
            for name in ("images", "masks", "gt_mesh.npz", "gt_texture.png", "body.npz", "cameras.json")
        }
        tot = _du(out)
        print(
            f"  disk: {tot / 2**20:.1f} MiB total = "
            + ", ".join(f"{k} {v / 2**20:.1f}" for k, v in sizes.items())
        )
        print(
            f"  per frame: images+masks {(sizes['images'] + sizes['masks']) / n / 1024:.0f} KiB, "
            f"ground-truth posed mesh {sizes['gt_mesh.npz'] / n / 1024:.0f} KiB"
        )
        if args.contact_sheet:
            contact_sheet(out, args.contact_sheet)


if __name__ == "__main__":
    main()
