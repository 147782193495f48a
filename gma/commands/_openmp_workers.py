"""Torch's idle OpenMP workers asleep while a CPU adapter renders: an opt-in of the ``gma`` command's
fits (``gma fit``, ``gma demo``), which enter it around every public render call through
:func:`gma.render.api.around_device_work`. It reaches into libgomp's ABI, which a library has no business
doing inside an application that embeds it; the command is the application here.

Torch runs its CPU ops on an OpenMP thread pool (libgomp on Linux). After each parallel op, libgomp's
worker threads spin-wait for the next one before they sleep (by default 300,000 pause instructions).
In a loop around ``gma.render.rasterize`` every user op before the render (the parameters' ``clone()``)
and before its backward (the loss) starts such a spin, on a core that lavapipe's threads need: on a
machine with few cores that time comes out of lavapipe's share (docs/design.md has the figures).
``OMP_WAIT_POLICY=passive`` stops the spin, but only when set before torch is imported, for the whole
process, and torch's own chains of ops lose by it.

:func:`openmp_workers_asleep` stops it only while GMA waits for the adapter: it opens a parallel
region of torch's pool (``GOMP_parallel_start``, libgomp's ABI for compiler-made code) whose workers
block in ``sem_wait``, asleep in the kernel, while the calling thread goes on as the region's master;
on leaving, it posts the semaphore once per worker, waits (asleep) until they have taken the posts, and
closes the region (``GOMP_parallel_end``). The
workers then return to the pool exactly as after any torch op (and spin, now beside the caller's own
work). In between, torch ops on the calling thread run on one thread (torch sees a parallel region), so
the region covers only GMA's own code, which keeps its host work in numpy.

It does nothing unless all of these hold: Linux, torch's parallel backend is OpenMP with libgomp
already loaded, torch uses more than one thread, the caller is the main thread (each thread that runs
torch ops has a pool of its own; another thread's region would make a new pool rather than quiet the
one that spins) and no region is open on it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import torch

_UNSET = object()
_gomp = _UNSET   # the loaded libgomp (a ctypes library) or None where parking does not apply
_libc = None


def _torch_libgomp() -> ctypes.CDLL | None:
    """The libgomp that torch's ops run on, opened only if it is already loaded; None where there is none."""
    if not sys.platform.startswith("linux") or "OpenMP" not in torch.__config__.parallel_info():
        return None
    try:
        with open("/proc/self/maps") as maps:
            fields = [line.split(None, 5) for line in maps if "libgomp" in line]
    except OSError:
        return None
    paths = {f[5].strip() for f in fields if len(f) == 6}
    paths = {p for p in paths if Path(p).name.startswith("libgomp")}
    torch_lib = str(Path(torch.__file__).resolve().parent / "lib")
    own = [p for p in paths if p.startswith(torch_lib)]
    candidates = own or sorted(paths)
    if len(candidates) != 1:   # none, or several and none of them torch's: not ours to guess
        return None
    try:
        lib = ctypes.CDLL(candidates[0], mode=os.RTLD_NOLOAD | os.RTLD_LAZY)
        lib.GOMP_parallel_start.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_uint]
        lib.GOMP_parallel_start.restype = None
        lib.GOMP_parallel_end.restype = None
        lib.omp_in_parallel.restype = ctypes.c_int
        lib.omp_get_num_threads.restype = ctypes.c_int
    except (OSError, AttributeError):
        return None
    return lib


def _library() -> ctypes.CDLL | None:
    global _gomp, _libc
    if _gomp is _UNSET:
        gomp = _torch_libgomp()
        if gomp is not None:
            _libc = ctypes.CDLL(None, use_errno=True)
            for name in ("sem_init", "sem_post", "sem_getvalue", "sem_destroy"):
                getattr(_libc, name).restype = ctypes.c_int
        _gomp = gomp
    return _gomp


def _applies() -> bool:
    if threading.current_thread() is not threading.main_thread() or torch.get_num_threads() < 2:
        return False
    gomp = _library()
    return gomp is not None and gomp.omp_in_parallel() == 0


@contextlib.contextmanager
def openmp_workers_asleep(active: bool = True) -> Iterator[bool]:
    """While the block runs, torch's idle OpenMP workers of the calling thread sleep instead of spinning
    (see the module's text); yields whether they do. ``active=False`` (e.g. a real GPU, whose work does not
    share the CPU) makes it a no-op."""
    if not (active and _applies()):
        yield False
        return
    gomp, libc = _gomp, _libc
    sem = (ctypes.c_long * 8)()   # a sem_t (32 bytes on x86-64 and aarch64), long-aligned
    if libc.sem_init(sem, 0, 0) != 0:
        yield False
        return
    sem_wait = ctypes.cast(libc.sem_wait, ctypes.c_void_p).value
    gomp.GOMP_parallel_start(sem_wait, ctypes.addressof(sem), torch.get_num_threads())
    try:
        yield True
    finally:
        # The master (this thread) does not run sem_wait; each worker takes one post. A worker whose
        # wait a signal interrupted has gone on to the region's end and leaves its post unused.
        for _ in range(gomp.omp_get_num_threads() - 1):
            libc.sem_post(sem)
        _until_taken(libc, sem)
        gomp.GOMP_parallel_end()
        libc.sem_destroy(sem)


def _until_taken(libc, sem) -> None:
    """Return once the workers have taken every post of ``sem`` (or after 1,000 short sleeps): 100 us of
    polling (a woken worker runs within tens of microseconds on an idle machine), then short sleeps.
    GOMP_parallel_end's barrier spins instead, and on a loaded machine that spin held the core that a woken
    worker waited for."""
    value = ctypes.c_int()
    for i in range(1200):
        if libc.sem_getvalue(sem, ctypes.byref(value)) != 0 or value.value <= 0:
            return
        if i >= 200:
            time.sleep(50e-6)
