"""``gma fit SEQ -o avatar.gma``: fit a Gaussian Morphing Avatar to a sequence (two stages: geometry
through coarse surfels and the mesh layer, then fine surfels). Options override the chosen preset;
the resolved config, checkpoint, metrics and previews go to ``<stem>.fit/`` beside the output (``me.fit/``
for ``-o me.gma``). ``--resume`` continues an interrupted fit from its last checkpoint; an existing avatar
is replaced only with ``--force``.

Sequences from ``gma import video`` (estimated poses) also get per-frame pose corrections and colour
transforms, learnt with the avatar (``--pose.refine``, ``--colour.refine``); the refined poses go to
``<output stem>.body.npz``. Without ``--preset`` they are fitted with the ``standard`` preset, other
sequences with ``quick``.

With several sequences (``gma fit SEQ1 SEQ2 ... -o DIR``) the decoders are shared, as in the paper: each
sequence gets its own avatar (``DIR/<sequence>.gma``, its own features and body identity) and the
decoders trained over all of them go to ``DIR/decoders.gma``. A new identity then fits only its
features against them: ``gma fit NEW -o new.gma --decoders DIR/decoders.gma``."""

from __future__ import annotations

import argparse

from gma.core.errors import InputError


def register(subparsers) -> None:
    from gma.commands._options import add_dataclass_options
    from gma.train.config import FitConfig

    p = subparsers.add_parser("fit", help="fit an avatar to a sequence", description=__doc__,
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("sequence", nargs="+", help="sequence directory (see docs/data.md); several train shared "
                                                "decoders")
    p.add_argument("-o", "--output", required=True, help="avatar file to write (.gma); a folder for several "
                                                         "sequences")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint in <stem>.fit/")
    p.add_argument("--force", action="store_true", help="overwrite an existing avatar; start over from an "
                                                        "interrupted fit's checkpoint")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_dataclass_options(p, FitConfig)
    p.set_defaults(func=run)


def _across_note(filled: dict | None) -> str:
    """The clause on body parts the frames showed nothing of (a clip of the upper body only: the legs)."""
    share = (filled or {}).get("across_groups", 0.0) + (filled or {}).get("by_mean", 0.0)
    if share <= 0:
        return ""
    return (f"; {100 * share:.0f} % of the faces lie on body parts no frame showed at all and took the colours "
            "of the nearest parts that were seen")


def run(args: argparse.Namespace) -> int:
    from gma.commands._openmp_workers import openmp_workers_asleep
    from gma.commands._options import collect_overrides
    from gma.data import read_sequence
    from gma.edit.unseen import AfterFit
    from gma.render.api import around_device_work
    from gma.train.config import preset
    from gma.train.outputs import prepare_fit_outputs
    from gma.train.trainer import Trainer, refined_body_path, work_dir

    if args.resume and args.force:
        raise InputError("--resume and --force contradict each other: continue the fit, or start it over")
    overrides = collect_overrides(args)
    cfg = preset(overrides.pop("preset", None) or default_preset(args.sequence), **overrides)
    prepare_fit_outputs(args.output, args.sequence, args.resume, args.force)  # before reading any image
    seqs = [read_sequence(s) for s in args.sequence]
    trainer = Trainer(cfg, seqs, args.output, progress=not args.quiet, finish=AfterFit())
    with around_device_work(openmp_workers_asleep):   # (the command's choice: see _openmp_workers.py)
        avatar = trainer.run(resume=args.resume)
    written = ", ".join(str(s.out) for s in trainer.subjects)
    if len(seqs) > 1:
        written += f" and the shared decoders {trainer.out / 'decoders.gma'}"
    print(f"wrote {written} ({avatar.info['fit_seconds']} s, {avatar.info['steps']} steps); "
          f"config, metrics and previews in {work_dir(trainer.out)}")
    for sub in trainer.subjects:
        if "unseen" in sub.avatar.info:
            g = sub.avatar.info["unseen"]["guessed"]
            print(f"{sub.out}: {100 * g['area']:.0f} % of the body surface ({100 * g['faces']:.0f} % of the faces) was "
                  "never seen well by the frames and was filled in from the seen faces (gma edit --select unseen)"
                  + _across_note(sub.avatar.info["unseen"].get("filled")))
        if sub.poses is not None:
            r = sub.avatar.info["pose_refinement"]
            print(f"refined poses of {sub.seq.root} in {refined_body_path(sub.out)} (mean correction "
                  f"{r['mean_bone_deg']:.1f} deg per bone, root {r['mean_root_deg']:.1f} deg / "
                  f"{r['mean_root_shift_cm']:.1f} cm)")
    return 0


def default_preset(sequences: list[str]) -> str:
    """The preset of a fit that names none: ``standard`` for sequences made by ``gma import video`` (a
    real person to show at full size), ``quick`` otherwise (synthetic and dataset sequences, demos)."""
    from pathlib import Path

    from gma.train.pose_refine import VIDEO_MARKER

    return "standard" if all((Path(s) / VIDEO_MARKER).is_file() for s in sequences) else "quick"
