"""``gma fit SEQ -o avatar.gma``: fit a Gaussian Morphing Avatar to a sequence (two stages: geometry
through coarse surfels and the mesh layer, then fine surfels). Options override the chosen preset;
the resolved config, checkpoint, metrics and previews go to ``<output>.fit/``. ``--resume`` continues
an interrupted fit from its last checkpoint."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    from gma.train.cli_config import add_dataclass_options
    from gma.train.config import FitConfig

    p = subparsers.add_parser("fit", help="fit an avatar to a sequence", description=__doc__,
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("sequence", help="sequence directory (see docs/data.md)")
    p.add_argument("-o", "--output", required=True, help="avatar file to write (.gma)")
    p.add_argument("--resume", action="store_true", help="continue from the checkpoint in <output>.fit/")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    add_dataclass_options(p, FitConfig)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from gma.data import read_sequence
    from gma.train.cli_config import collect_overrides
    from gma.train.config import preset
    from gma.train.trainer import Trainer, work_dir

    overrides = collect_overrides(args)
    cfg = preset(overrides.pop("preset", "quick"), **overrides)
    seq = read_sequence(args.sequence)
    trainer = Trainer(cfg, seq, args.output, progress=not args.quiet)
    avatar = trainer.run(resume=args.resume)
    print(f"wrote {args.output} ({avatar.info['fit_seconds']} s, {avatar.info['steps']} steps); "
          f"config, metrics and previews in {work_dir(trainer.out)}")
    return 0
