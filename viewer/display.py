"""A virtual display for scripts that open the viewer's window on a machine without a screen (the
benchmarks, the scripted screen recording): Xvfb on a free display number, which Xvfb picks itself
(``-displayfd``): scripts started together (the test suite's benchmark smoke runs) once both saw the same
number free, and the one whose Xvfb lost the race drew on the other's, and died with it (XIO error)."""

from __future__ import annotations

import os
import select
import shutil
import subprocess

from gma.core.errors import DeviceError

__all__ = ["ensure_display"]

START_TIMEOUT_S = 10.0


def ensure_display(screen: str = "1280x1024x24") -> subprocess.Popen | None:
    """Start Xvfb and point ``DISPLAY`` at it, unless a display is already set (then None). Returns the
    Xvfb process for the caller to terminate."""
    if os.environ.get("DISPLAY"):
        return None
    exe = shutil.which("Xvfb")
    if exe is None:
        raise DeviceError("no DISPLAY and no Xvfb to start one: cannot open a window (apt-get install xvfb)")
    read_end, write_end = os.pipe()
    try:
        proc = subprocess.Popen([exe, "-displayfd", str(write_end), "-screen", "0", screen, "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, pass_fds=(write_end,))
        os.close(write_end)
        write_end = -1
        # Xvfb writes the number once it listens; EOF or silence means it failed to start.
        ready, _, _ = select.select([read_end], [], [], START_TIMEOUT_S)
        number = os.read(read_end, 64).decode().strip() if ready else ""
    finally:
        os.close(read_end)
        if write_end >= 0:
            os.close(write_end)
    if not number.isdigit() or proc.poll() is not None:
        proc.kill()
        raise DeviceError("Xvfb did not start: cannot open a window (try xvfb-run, or set DISPLAY)")
    os.environ["DISPLAY"] = f":{number}"
    return proc
