"""A virtual display for scripts that open the viewer's window on a machine without a screen (the
benchmarks, the scripted screen recording): Xvfb on the first free display number. Scripts started
together (the test suite's benchmark smoke runs) may both find a number free and both start Xvfb on it:
the one whose server did not get the display's lock file (which holds the winner's pid) tries the next
number, instead of drawing on the winner's server and dying with it (XIO error)."""

from __future__ import annotations

import os
import shutil
import subprocess
import time

from gma.core.errors import DeviceError

__all__ = ["ensure_display"]


def ensure_display(screen: str = "1280x1024x24", first: int = 171, last: int = 199) -> subprocess.Popen | None:
    """Start Xvfb and point ``DISPLAY`` at it, unless a display is already set (then None). Returns the
    Xvfb process for the caller to terminate."""
    if os.environ.get("DISPLAY"):
        return None
    exe = shutil.which("Xvfb")
    if exe is None:
        raise DeviceError("no DISPLAY and no Xvfb to start one: cannot open a window (apt-get install xvfb)")
    for num in range(first, last + 1):
        if os.path.exists(f"/tmp/.X{num}-lock") or os.path.exists(f"/tmp/.X11-unix/X{num}"):
            continue
        proc = subprocess.Popen([exe, f":{num}", "-screen", "0", screen, "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(50):  # wait until the server listens (or has died)
            if os.path.exists(f"/tmp/.X11-unix/X{num}") or proc.poll() is not None:
                break
            time.sleep(0.1)
        if proc.poll() is None and _lock_owner(num) == proc.pid:
            os.environ["DISPLAY"] = f":{num}"
            return proc
        proc.kill()
        proc.wait()
    raise DeviceError(f"could not start Xvfb on any display :{first}-:{last}")


def _lock_owner(num: int) -> int | None:
    """The pid in display ``num``'s lock file (Xvfb writes it before it listens), or None."""
    try:
        with open(f"/tmp/.X{num}-lock") as f:
            return int(f.read().strip())
    except (OSError, ValueError):
        return None
