"""The side the camera never saw, on real footage: the iPER turn clip (docs/data.md, "Real footage") cut
down to the frames where the person faces the camera within +-60 deg (a front-only clip), fitted with
the quick preset as ``gma fit`` does, and the faces left at the untrained default colour counted before
and after the fill of the unseen faces (``gma.edit.unseen``).

The frames are chosen by the imported poses' root yaw (:func:`root_yaw`: the angle between the body's
forward axis and the direction to the camera). Two counts of faces left at the untrained default:

- *untrained* (:func:`gma.edit.unseen.untrained_faces`): texture features still exactly those the fit
  started the face with, so it decodes to the untrained default colour by construction;
- *at the default colour* (:func:`gma.edit.unseen.default_colour_faces`): decoded colour within
  ``--tolerance`` (0-1, every channel, every surfel) of what the fitted decoders make of the face's
  starting features. Faces the fit did train land that close by chance too; their share among the
  faces seen well is printed beside it as the chance rate.

Writes ``--figure``: the avatar in its canonical pose from the front, then from behind before and after
the fill; prints the counts, and the PSNR and colour error on the clip's frames that show the person's
back (beyond 150 deg; their poses as imported, not refined by the fit); also ``--work``/results.json.
An import or a fit already in ``--work`` is reused; ``--imported`` takes an existing ``gma import video``
of the clip instead of importing it again.

    python benchmarks/unseen_real.py [--imported FOLDER] [--work out/bench_unseen_real]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import iper_clip, iper_missing, machine  # noqa: E402
from unseen_sides import score_views  # noqa: E402

from gma.body import load_body  # noqa: E402
from gma.data import read_sequence  # noqa: E402
from gma.edit.unseen import AfterFit, default_colour_faces, initial_features, untrained_faces  # noqa: E402
from gma.gpu import get_context  # noqa: E402
from gma.render.image_io import save_png  # noqa: E402
from gma.train.config import preset  # noqa: E402
from gma.train.trainer import Trainer  # noqa: E402


def root_yaw(seq, body) -> np.ndarray:
    """[T] degrees: per frame, the turn of the body's forward axis (left x up) away from the direction to
    the camera, about the up axis (0: facing the camera, +-180: its back to it)."""
    up = np.eye(3)[{"x": 0, "y": 1, "z": 2}[body.up_axis]]
    forward = np.cross(np.eye(3)[0], up)
    root = np.asarray(seq.body.arrays["pose"])[:, 0, :3, :3] @ forward  # [T, 3] in the world (Anny: root bone)
    yaw = []
    for t in range(len(seq)):
        _, w2c = seq.cameras.frame(t)
        to_camera = -np.asarray(w2c)[2, :3]  # the camera's optical axis, reversed, in the world
        f = root[t] - (root[t] @ up) * up
        c = to_camera - (to_camera @ up) * up
        yaw.append(np.degrees(np.arctan2(np.cross(c, f) @ up, f @ c)))
    return np.asarray(yaw)


def front_only_copy(imported: Path, out: Path, body, max_yaw: float):
    """A copy of an imported sequence (images linked, not copied) whose training split is the frames
    within ``max_yaw`` of facing the camera; the frames with their back to it (beyond 150 deg) are the
    split ``back``."""
    seq = read_sequence(imported)
    yaw = root_yaw(seq, body)
    out.mkdir(parents=True, exist_ok=True)
    for name in ("images", "masks", "cameras.json", "body.npz"):
        link = out / name
        if not link.exists():
            link.symlink_to((imported / name).resolve())
    splits = {"train": [t for t in range(len(yaw)) if abs(yaw[t]) <= max_yaw],
              "back": [t for t in range(len(yaw)) if abs(yaw[t]) >= 150]}
    (out / "splits.json").write_text(json.dumps(splits))
    return read_sequence(out), yaw


@torch.no_grad()
def views(avatar, body, ctx, size: int) -> list[np.ndarray]:
    """The avatar in the canonical pose from the front and from behind, on white."""
    from gma.avatar.gpu import AvatarRenderer
    from gma.edit import Editor

    ed = Editor(avatar, body, ctx)
    renderer = AvatarRenderer(ctx, avatar, body, decoded=ed.decoded)
    return [renderer.render(ed.params(), ed.named_view(name, size, size).camera, (1.0, 1.0, 1.0))
            for name in ("front", "back")]


def _defaults(avatar, start, tolerance: float) -> dict[str, np.ndarray]:
    """[F] bool masks of the faces left at the untrained default, by both counts (module docstring)."""
    return {"untrained": untrained_faces(avatar.model, start),
            "default_colour": default_colour_faces(avatar.model, start, tolerance)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--imported", help="a 'gma import video' of the clip (default: import it into --work)")
    ap.add_argument("--work", default="out/bench_unseen_real", help="folder for the import, the fit and results")
    ap.add_argument("--figure", default="docs/unseen_iper_back.png",
                    help="front | back before the fill | back after")
    ap.add_argument("--max-yaw", type=float, default=60.0, help="training frames: within this of the front (deg)")
    ap.add_argument("--tolerance", type=float, default=0.02, help="of the default colour (0-1)")
    ap.add_argument("--size", type=int, default=320, help="figure panel size (pixels)")
    args = ap.parse_args(argv)
    if not 0 < args.max_yaw < 180 or not 0 < args.tolerance < 1:
        ap.error("need 0 < --max-yaw < 180 and 0 < --tolerance < 1")
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    imported = Path(args.imported) if args.imported else work / "iper"
    if not (imported / "splits.json").is_file() and not args.imported:
        clip = iper_clip()
        if not clip.is_file():
            print(iper_missing(clip))
            return 2
        from gma.video import estimate_sequence

        estimate_sequence(clip, imported, anny=load_body("anny"), progress=False)
    ctx, body = get_context(), load_body("anny")
    seq, yaw = front_only_copy(imported, work / "front_only", body, args.max_yaw)
    cfg = preset("quick", preview_every=0)
    out = work / "front_only.gma"
    t0 = time.perf_counter()
    trainer = Trainer(cfg, seq, out, ctx=ctx, progress=False)
    avatar = trainer.run(resume=True)  # without a finish step: the avatar as the fit left it
    fit_s = time.perf_counter() - t0
    start = initial_features(avatar, cfg.seed)
    before = _defaults(avatar, start, args.tolerance)
    picture = views(avatar, body, ctx, args.size)
    back_before, _ = score_views(avatar, seq, "back", cfg.resolution, body, ctx)
    t0 = time.perf_counter()
    summary = AfterFit(ctx)(avatar, body, trainer.posed_meshes(0), mirror=cfg.symmetry > 0)
    fill_s = time.perf_counter() - t0
    after = _defaults(avatar, start, args.tolerance)
    seen = avatar.face_seen.numpy()
    unseen, seen_well = seen < 0.5, seen >= 0.8
    picture.append(views(avatar, body, ctx, args.size)[1])
    back_after, _ = score_views(avatar, seq, "back", cfg.resolution, body, ctx)
    save_png(Path(args.figure), np.concatenate(picture, 1))
    result = {"frames": len(seq), "train_frames": len(seq.split("train")), "yaw_deg": np.round(yaw, 1).tolist(),
              "fit_s": round(fit_s, 1), "fill_s": round(fill_s, 1), "tolerance": args.tolerance,
              "faces": int(len(unseen)), "unseen_faces": int(unseen.sum()), "guessed": summary["guessed"],
              "seen_well_faces": int(seen_well.sum()), "back_before": back_before, "back_after": back_after}
    for when, counts in (("before", before), ("after", after)):
        result[when] = {name: {"all": int(m.sum()), "unseen": int(m[unseen].sum()),
                               "seen_well": int(m[seen_well].sum())} for name, m in counts.items()}
    print(f"# unseen sides on real footage: {machine()}; iPER turn, {result['train_frames']} of {len(seq)} frames "
          f"within +-{args.max_yaw:g} deg of the front, quick preset")
    print(f"guessed: {100 * summary['guessed']['area']:.0f} % of the surface, {result['unseen_faces']} of "
          f"{result['faces']} faces; fill {result['fill_s']} s")
    print(f"frames with the back to the camera ({back_before['frames']}, poses as imported, {cfg.resolution} px): PSNR "
          f"{back_before['psnr']:.2f} -> {back_after['psnr']:.2f} dB, colour error {back_before['colour_error']:.1f} "
          f"-> {back_after['colour_error']:.1f}")
    print("| faces | before the fill | after | of them unseen (before / after) | chance rate (seen well, after) |")
    print("|---|---|---|---|---|")
    for name, label in (("untrained", "untrained features"),
                        ("default_colour", f"at the default colour (tolerance {args.tolerance:g})")):
        b, a = result["before"][name], result["after"][name]
        print(f"| {label} | {b['all']} | {a['all']} | {b['unseen']} / {a['unseen']} | "
              f"{100 * a['seen_well'] / max(result['seen_well_faces'], 1):.2f} % |")
    (work / "results.json").write_text(json.dumps({"args": vars(args), "machine": machine(), "result": result},
                                                  indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
