"""``gma batch VIDEOS_OR_SEQUENCES... -o OUT``: many people at once on Ray (``pip install 'gma[cluster]'``).
One task per person goes through the single-person steps (video import, fit, eval, export, a turntable
video) into ``OUT/<name>/``, with a status file; re-running the same command skips what finished and
resumes what was interrupted (the fit from its checkpoint); a failed person is recorded and the others go
on. ``OUT/summary.csv`` and ``summary.md`` list every person.

Without ``--address`` a local Ray runtime starts on this machine; ``--address auto`` joins a running
cluster (``ray start --head`` / ``ray up``), ``ray://host:port`` a remote one. Fit options as ``gma fit``.
Shared decoders (the paper's setup): ``--train-decoders N`` trains them on the first N people, then fits only
the features of the others against them, in parallel; ``--decoders FILE`` uses existing ones for everyone."""

from __future__ import annotations

import argparse

from gma.core.args import non_negative_float, non_negative_int, positive_int


def _steps(text: str) -> tuple[str, ...]:
    return tuple(s.strip() for s in text.split(",") if s.strip())


def register(subparsers) -> None:
    from gma.commands._options import add_dataclass_options
    from gma.train.config import FitConfig

    p = subparsers.add_parser("batch", help="fit many people at once on Ray (gma[cluster])", description=__doc__,
                              formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("inputs", nargs="+", metavar="VIDEO_OR_SEQUENCE", help="videos and/or sequence folders")
    p.add_argument("-o", "--output", required=True, help="batch folder: OUT/<name>/ per person, summary.csv/.md")
    p.add_argument("--steps", type=_steps, default="import,fit,eval,export,video",
                   help="steps per person, in order (import is skipped for sequences; export needs gma export)")
    p.add_argument("--train-decoders", type=non_negative_int, default=0, metavar="N",
                   help="train shared decoders on the first N people, then fit the others' features against them")
    p.add_argument("--address", default="", help="Ray cluster: auto or ray://host:port (default: a local runtime)")
    p.add_argument("--cpus-per-task", type=non_negative_float, default=1.0, help="CPU cores Ray reserves per person")
    p.add_argument("--gpus-per-task", type=non_negative_float, default=0.0,
                   help="GPUs Ray reserves per person (fractions share a GPU)")
    p.add_argument("--eval-resolution", type=positive_int, default=512, help="longest image side of the evaluation")
    p.add_argument("--video-size", type=positive_int, default=256, help="turntable video frame size")
    p.add_argument("--video-frames", type=positive_int, default=72, help="turntable video frames")
    p.add_argument("--export-format", choices=("3dgs", "2dgs"), default="3dgs",
                   help="export step: splat PLY layout of the canonical pose")
    p.add_argument("--quiet", action="store_true", help="no progress display")
    add_dataclass_options(p, FitConfig)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from gma.batch import BatchConfig, find_people
    from gma.batch.cluster import import_ray
    from gma.batch.summary import format_markdown
    from gma.commands._options import collect_overrides
    from gma.core.errors import MissingFileError
    from gma.train.config import FitConfig, preset

    steps = args.steps if isinstance(args.steps, tuple) else _steps(args.steps)
    batch = BatchConfig(steps=steps, train_decoders=args.train_decoders, address=args.address,
                        cpus_per_task=args.cpus_per_task, gpus_per_task=args.gpus_per_task,
                        eval_resolution=args.eval_resolution, video_size=args.video_size,
                        video_frames=args.video_frames, export_format=args.export_format)
    overrides = collect_overrides(args)
    fit = preset(overrides.pop("preset", "quick"), **overrides)
    if fit.decoders:  # workers may run elsewhere: they get the absolute path
        if not Path(fit.decoders).is_file():
            raise MissingFileError(f"{fit.decoders}: decoders file not found")
        from gma.avatar.decoders import load_decoders

        load_decoders(fit.decoders, fit.avatar)  # a damaged or mismatched file: one line here, not one per person
        fit = FitConfig.from_dict({**fit.to_dict(), "decoders": str(Path(fit.decoders).resolve())})
    people = find_people(args.inputs)
    import_ray()  # its one-line error comes before torch and the body model load

    from gma.batch.runner import run_batch

    rows = run_batch(people, args.output, batch, fit, progress=not args.quiet)
    print(format_markdown(rows), end="")
    print(f"wrote {args.output}/summary.csv and summary.md")
    return 0 if all(r["status"] == "done" for r in rows) else 1
