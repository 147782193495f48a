"""The virtual display the window benchmarks start (viewer/display.py): scripts started together get
displays of their own (a server that did not win a number's lock file moves on), so one ending never takes
another's display."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from viewer.display import ensure_display

pytestmark = pytest.mark.skipif(shutil.which("Xvfb") is None, reason="needs Xvfb")
REPO = Path(__file__).resolve().parents[1]


def test_displays_started_together_are_distinct():
    # Six processes start a display at the same moment (each waits for "go" after its imports), as the
    # benchmark smoke runs can; each prints its DISPLAY, then keeps its Xvfb until stdin closes.
    code = (f"import os, sys; sys.path.insert(0, {str(REPO)!r}); os.environ.pop('DISPLAY', None); "
            "from viewer.display import ensure_display; print('ready', flush=True); sys.stdin.readline(); "
            "p = ensure_display('64x64x24'); print(os.environ['DISPLAY'], flush=True); sys.stdin.read(); "
            "p.terminate()")
    procs = [subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                              text=True) for _ in range(6)]
    for p in procs:
        assert p.stdout.readline().strip() == "ready"
    for p in procs:
        p.stdin.write("go\n")
        p.stdin.flush()
    displays = [p.stdout.readline().strip() for p in procs]
    for p in procs:
        p.communicate("", timeout=30)
    assert all(d.startswith(":") for d in displays), displays
    assert len(set(displays)) == len(displays), displays


def test_an_existing_display_is_kept(monkeypatch):
    monkeypatch.setenv("DISPLAY", ":4242")
    assert ensure_display() is None
    assert os.environ["DISPLAY"] == ":4242"
