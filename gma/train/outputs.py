"""What a fit writes, checked before the fit starts: the avatar file(s), the shared decoders, and the
work folder ``<stem>.fit/`` with its checkpoint. A fit never silently replaces a finished avatar or the
checkpoint of an interrupted fit: the first needs ``--force``, the second ``--resume`` (continue) or
``--force`` (start over)."""

from __future__ import annotations

import json
from pathlib import Path

from gma.core.errors import InputError, OutputExistsError
from gma.core.outputs import prepare_output_file
from gma.train.trainer import CHECKPOINT_NAME, subject_outputs, work_dir

__all__ = ["CHECKPOINT_NAME", "prepare_fit_outputs"]


def prepare_fit_outputs(out: str | Path, seqs: list, resume: bool = False, force: bool = False) -> list[Path]:
    """Check every output of a fit of ``seqs`` into ``out``; returns the avatar paths. With ``force`` (and
    no ``resume``) an interrupted fit's checkpoint is removed so that the new fit starts from step 0.
    Raises :class:`gma.core.errors.GmaError` subclasses naming the path."""
    out = Path(out)
    if len(seqs) == 1 and out.suffix.lower() != ".gma":
        raise InputError(f"{out}: the avatar file must end in .gma")
    avatars = subject_outputs(out, [getattr(s, "root", s) for s in seqs])  # Sequence objects or folders
    checkpoint = work_dir(out) / CHECKPOINT_NAME
    interrupted = checkpoint.is_file()
    if interrupted and not (resume or force):
        raise OutputExistsError(f"an interrupted fit exists at {work_dir(out)}: --resume to continue, --force to "
                                "start over")
    # --resume continues a fit, which rewrites its own outputs at the end.
    replace = force or resume
    for path in avatars:
        prepare_output_file(path, replace, "avatar")
    if len(seqs) > 1:
        prepare_output_file(out / "decoders.gma", replace, "decoders file")
    prepare_output_file(checkpoint, True, "checkpoint")  # the work folder must be writable too
    if interrupted and resume:
        saved = work_dir(out) / "config.json"
        try:
            json.loads(saved.read_text())
        except (OSError, ValueError) as exc:
            raise InputError(f"{saved}: the interrupted fit's config cannot be read ({exc}); --force starts the "
                             "fit over") from None
    if interrupted and force and not resume:
        checkpoint.unlink()
    return avatars
