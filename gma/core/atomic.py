"""Crash-safe writes: a file appears complete or not at all, and so does a sequence directory.

Files are written to a temporary name in the same directory, flushed and fsynced, then renamed over
the target (``os.replace`` is atomic on POSIX and Windows when both names are on one filesystem).
Directories are built under a hidden temporary name next to the target and renamed into place at
the end, so an interrupted ``gma synth`` or ``gma import`` never leaves a half-written sequence that
a later ``gma fit`` would read.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import tempfile
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from gma.core.errors import OutputExistsError

__all__ = ["atomic_dir", "atomic_file", "atomic_write_bytes", "atomic_write_json", "atomic_write_npz",
           "ordinary_mode", "temp_prefix", "writer_is_alive"]


def temp_prefix(path: Path) -> str:
    """The hidden prefix of a temporary file or folder beside ``path``. It names the writing process, so
    that the clean-up of an earlier killed run (:func:`gma.core.outputs.clean_stale`) can tell litter from
    the work in progress of another process writing the same output at the same moment."""
    return f".{path.name}.{os.getpid()}-"


def writer_is_alive(temp_name: str, path: Path) -> bool:
    """Whether the process that made the temporary ``temp_name`` beside ``path`` still runs (names without
    a process id are an older layout: taken as litter)."""
    pid = temp_name[len(f".{path.name}."):].split("-", 1)[0]
    if not pid.isdigit():
        return False
    try:
        os.kill(int(pid), 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # another user's process
    return True


def ordinary_mode(folder: bool = False) -> int:
    """The permissions a new file (or ``folder``) gets from the umask. mkstemp/mkdtemp make private ones
    (0600/0700); an output is an ordinary user file, so temporaries are given this before the rename."""
    mask = os.umask(0)  # the umask can only be read by setting it; set it straight back
    os.umask(mask)
    return (0o777 if folder else 0o666) & ~mask


def _fsync_dir(path: Path) -> None:
    # Persist the rename itself; not possible (nor needed) on Windows.
    if os.name != "nt":
        fd = os.open(path, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` to write; on success it is fsynced and renamed to ``path``
    (readers see the old file or the complete new one), on an exception removed."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=temp_prefix(path), suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    os.chmod(tmp_path, ordinary_mode())
    try:
        yield tmp_path
        with open(tmp_path, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp_path, path)
        _fsync_dir(path.parent)
    except BaseException:
        tmp_path.unlink(missing_ok=True)
        raise


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> None:
    """Write ``data`` to ``path`` so that readers see either the old file or the complete new one."""
    with atomic_file(Path(path)) as tmp:
        tmp.write_bytes(data)


def atomic_write_json(path: str | os.PathLike, obj) -> None:
    """Atomically write ``obj`` as indented JSON (numpy scalars and arrays become plain lists)."""

    def default(o):
        if isinstance(o, np.ndarray):
            return o.tolist()
        if isinstance(o, np.generic):
            return o.item()
        raise TypeError(f"{type(o).__name__} is not JSON serialisable")

    atomic_write_bytes(path, (json.dumps(obj, indent=1, default=default) + "\n").encode())


def atomic_write_npz(path: str | os.PathLike, **arrays) -> None:
    """Atomically write an uncompressed ``.npz``; object arrays are refused so that the file can be
    read back with ``allow_pickle=False``."""
    for key, value in arrays.items():
        if np.asarray(value).dtype == object:
            raise TypeError(f"{path}: array {key!r} has dtype object, which would need pickle")
    with atomic_file(Path(path)) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **arrays)


@contextlib.contextmanager
def atomic_dir(path: str | os.PathLike, overwrite: bool = False) -> Iterator[Path]:
    """Build a directory under a temporary name and move it to ``path`` when the block succeeds.

    Yields the temporary directory. On an exception it is removed and ``path`` is left untouched.
    With ``overwrite`` an existing ``path`` is replaced (moved aside first, deleted after the rename,
    so a crash between the two steps leaves the old copy under a hidden ``.old`` name, never a mix).
    """
    path = Path(path)
    if path.exists() and not overwrite:
        raise OutputExistsError(f"{path}: already exists; pass --force to replace it")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=temp_prefix(path), suffix=".partial", dir=path.parent))
    os.chmod(tmp, ordinary_mode(folder=True))
    try:
        yield tmp
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    old = None
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=temp_prefix(path), suffix=".old", dir=path.parent))
        os.replace(path, old / "dir")
    os.replace(tmp, path)
    _fsync_dir(path.parent)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
