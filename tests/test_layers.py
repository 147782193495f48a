"""The project's structure stays as designed: layers import one way (import-linter contracts in
pyproject.toml), every import is a declared dependency (deptry), and ``gma --help`` loads no heavy layer."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _run(*cmd: str) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, timeout=120)


def test_layers_import_one_way():
    pytest.importorskip("importlinter")
    out = _run(sys.executable, "-c", "import sys; from importlinter.cli import lint_imports_command; "
               "sys.exit(lint_imports_command())")
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]


def test_every_import_is_a_declared_dependency():
    pytest.importorskip("deptry")
    out = _run(sys.executable, "-m", "deptry", ".")
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-2000:]


def test_help_loads_no_heavy_module():
    code = ("import sys, contextlib, io\nfrom gma.cli import build_parser\n"
            "with contextlib.redirect_stdout(io.StringIO()):\n"
            "    try:\n        build_parser().parse_args(['fit', '--help'])\n    except SystemExit:\n        pass\n"
            "print(sorted(m for m in ('torch', 'wgpu', 'anny') if m in sys.modules))")
    t0 = time.perf_counter()
    out = _run(sys.executable, "-c", code)
    elapsed = time.perf_counter() - t0
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]", f"gma --help imported {out.stdout.strip()}"
    assert elapsed < 5.0  # generous: the figure is ~0.2 s; this only catches a heavy import sneaking back
