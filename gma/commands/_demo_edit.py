"""The editing part of ``gma demo``: what the method is for. A second synthetic person is fitted against
the first avatar's frozen decoders (the paper's shared decoders: features only), then the first avatar
gets the showcase edits of :mod:`gma.edit.showcase` — a painted sleeve, a logo on the chest, mirrored
cuffs and the second person's trousers — and an ``edited_turntable.mp4`` beside the original one. Every
step resumes or is reused when the demo runs again."""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from gma.avatar import Avatar
from gma.avatar.gpu import AvatarRenderer
from gma.avatar.video import render_turntable, write_video
from gma.data import read_sequence
from gma.edit import Editor
from gma.edit.showcase import run_showcase
from gma.render.image_io import save_png
from gma.synth.generate import SynthConfig, synthesize
from gma.train.config import preset
from gma.train.trainer import Trainer

__all__ = ["edit_stage"]


def edit_stage(out: Path, avatar_path: Path, preset_name: str, seed: int, body, ctx, cameras: tuple,
               background: float, size: int) -> dict:
    """Fit the donor, edit a copy of the avatar, write ``edited.gma``, before/after pictures in ``edits/``
    and ``edited_turntable.mp4``. ``cameras`` = (K [3, 3] scaled to ``size``, w2c [4, 4]) of the turntable.
    Returns {"times_s": {...}, "edits": [...], "files": [...]}."""
    times: dict[str, float] = {}
    t0 = time.perf_counter()
    donor_dir = out / "donor_sequence"
    if (donor_dir / "splits.json").is_file():
        donor_seq = read_sequence(donor_dir)
    else:  # another person: other clothes, texture and body shape
        donor_seq = synthesize(donor_dir, SynthConfig(seed=seed + 1), ctx=ctx, body=body)
    donor_cfg = preset(preset_name, seed=seed + 1, decoders=str(avatar_path))
    donor = Trainer(donor_cfg, donor_seq, out / "donor.gma", body=body, ctx=ctx).run(resume=True)
    times["donor_fit_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    avatar = Avatar.load(avatar_path, body)  # a fresh copy: the fitted avatar.gma stays as it was
    ed = Editor(avatar, body, ctx)
    renderer = AvatarRenderer(ctx, avatar, body, decoded=ed.decoded)
    bg = (background,) * 3
    pictures, edits = [], []

    def picture(edit, views, apply):
        view = views[edit.view]
        before = renderer.render(ed.params(), view.camera, bg)
        t = time.perf_counter()
        change = apply()
        seconds = time.perf_counter() - t
        renderer.update_rows(change.rows, change.mesh)
        after = renderer.render(ed.params(), view.camera, bg)
        path = save_png(out / "edits" / f"{edit.name}.png", np.concatenate([before, after], 1))
        pictures.append(str(path))
        edits.append({"edit": edit.title, "faces": len(change.faces), "seconds": round(seconds, 2)})
        print(f"[demo] {edit.title}: {len(change.faces)} faces in {seconds:.2f} s")
        return change

    run_showcase(ed, donor, 256, picture)
    edited_path = avatar.save(out / "edited.gma")
    times["edit_s"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    K, w2c = cameras
    frames = render_turntable(renderer, body.canonical_params(avatar.shape), K, w2c, size, 72, bg)
    video = write_video(out / "edited_turntable.mp4", frames)
    times["edited_video_s"] = time.perf_counter() - t0
    return {"times_s": times, "edits": edits, "files": [str(edited_path), str(video), *pictures]}
