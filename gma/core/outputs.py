"""Checks on outputs before any expensive work, and the rules for replacing them.

Every command that writes calls one of these first, so that a run that cannot write its result fails
in well under a second instead of after the work, and so that ``--force`` never removes what GMA did
not make:

- :func:`prepare_output_file`: the folder can be written, the path is not a folder, and an existing
  file is replaced only with ``force``.
- :func:`prepare_output_dir`: the same for a folder output (a sequence, a folder of PNGs); with
  ``force`` an existing folder is replaced only when ``is_ours`` recognises it as GMA's own output of
  that kind, and never when it is the current folder, one of its parents, the home folder or ``/``.

Both remove the litter that an earlier killed run of the same output left: hidden ``.NAME.*.tmp`` (or
``.NAME.*.tmp.EXT``) files and ``.NAME.*.partial`` folders, and ``.NAME.*.old`` folders when the output
itself exists; when it does not, the ``.old`` copy is the last complete output and is moved back.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from pathlib import Path

from gma.core.atomic import writer_is_alive
from gma.core.errors import OutputError, OutputExistsError

__all__ = ["clean_stale", "prepare_output_dir", "prepare_output_file"]


def _writable_parent(path: Path) -> None:
    """The nearest existing ancestor of ``path`` must be a writable folder (missing ones get created)."""
    parent = path.parent
    while not parent.exists():
        if parent.parent == parent:
            break
        parent = parent.parent
    if not parent.is_dir():
        raise OutputError(f"{path}: cannot be written, {parent} is a file, not a folder")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise OutputError(f"{path}: cannot be written, the folder {parent} is not writable")


def clean_stale(path: Path) -> None:
    """Remove what an interrupted atomic write of ``path`` left beside it (see the module doc). What a
    running process is writing right now is left alone: two runs may write the same output at once, and
    then the last complete file wins."""
    parent = path.parent
    if not parent.is_dir():
        return
    prefix = f".{path.name}."
    for entry in parent.iterdir():
        name = entry.name
        if not name.startswith(prefix) or writer_is_alive(name, path):
            continue
        if (name.endswith(".tmp") or ".tmp." in name) and entry.is_file():
            entry.unlink(missing_ok=True)
        elif name.endswith(".partial") and entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        elif name.endswith(".old") and entry.is_dir():
            kept = entry / "dir"
            if not path.exists() and kept.is_dir():
                os.replace(kept, path)  # killed between the two renames of a replacement: restore
            shutil.rmtree(entry, ignore_errors=True)


def prepare_output_file(path: str | os.PathLike, force: bool = False, what: str = "output") -> Path:
    """Check that ``path`` may be written as a file; returns it as a Path. Raises :class:`OutputError`."""
    path = Path(path)
    if path.is_dir():
        raise OutputError(f"{path}: is a folder; the {what} is a file (give a file name)")
    _writable_parent(path)
    if path.exists():
        if not force:
            raise OutputExistsError(f"{path}: already exists; pass --force to overwrite it")
        if not os.access(path, os.W_OK) and not os.access(path.parent, os.W_OK):
            raise OutputError(f"{path}: exists and cannot be replaced (no write permission)")
    clean_stale(path)
    return path


def _protected(path: Path) -> bool:
    """The current folder, its parents, the home folder and the root are never replaced."""
    resolved = path.resolve()
    cwd = Path.cwd().resolve()
    return resolved == cwd or resolved in cwd.parents or resolved == Path.home().resolve() or \
        resolved == Path(resolved.anchor)


def prepare_output_dir(path: str | os.PathLike, force: bool = False, what: str = "output folder",
                       is_ours: Callable[[Path], str | None] | None = None) -> Path:
    """Check that the folder ``path`` may be (re)created. ``is_ours(path)`` returns None when an existing
    folder is GMA's own output of this kind (so ``force`` may replace it), else the reason it is not.
    Raises :class:`OutputError`."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise OutputError(f"{path}: is a file; the {what} is a folder")
    _writable_parent(path)
    if path.exists():
        if not force:
            raise OutputExistsError(f"{path}: already exists; pass --force to replace it")
        if _protected(path):
            raise OutputError(f"{path}: refusing to replace the current folder, one of its parents, the home "
                              "folder or / (name a new folder)")
        why = "not checked" if is_ours is None else is_ours(path)
        if why is not None:
            raise OutputError(f"{path}: --force replaces only a {what} made by GMA, and this folder is not one "
                              f"({why}); remove it yourself or name another folder")
    clean_stale(path)
    return path
