"""The project's structure stays as designed: layers import one way (import-linter contracts in
pyproject.toml), every import is a declared dependency (deptry), and ``gma --help`` loads no heavy layer."""

from __future__ import annotations

import ast
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


# Where the process environment may be prepared and the process tuned: the command line is the application.
APPLICATION = ("gma/commands/", "gma/cli.py")
ENV_WRITERS = {"setdefault", "update", "pop", "popitem", "clear", "__setitem__", "__delitem__"}


def _is_environ(node) -> bool:
    """``os.environ`` or a bare ``environ``."""
    return (isinstance(node, ast.Attribute) and node.attr == "environ") or (
        isinstance(node, ast.Name) and node.id == "environ")


def _process_changes(tree: ast.AST) -> list[str]:
    """What a module does to its process: environment writes, libgomp/ctypes library loads, downloads."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.Assign, ast.AugAssign, ast.Delete)):
            targets = node.targets if isinstance(node, (ast.Assign, ast.Delete)) else [node.target]
            found += [f"line {node.lineno}: writes os.environ" for t in targets
                      if isinstance(t, ast.Subscript) and _is_environ(t.value)]
        elif isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            if node.func.attr in ENV_WRITERS and _is_environ(node.func.value):
                found.append(f"line {node.lineno}: os.environ.{node.func.attr}")
            elif node.func.attr in ("putenv", "unsetenv", "CDLL", "LoadLibrary"):
                found.append(f"line {node.lineno}: {node.func.attr}")
        elif isinstance(node, (ast.Import, ast.ImportFrom)):
            names = [a.name for a in node.names] + ([node.module] if isinstance(node, ast.ImportFrom) else [])
            found += [f"line {node.lineno}: imports {n}" for n in names if n and n.startswith("urllib.request")]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) and "GOMP_" in node.value:
            found.append(f"line {node.lineno}: libgomp's ABI")
    return found


def test_the_library_leaves_the_process_alone():
    """No module under gma/ but the command line's writes environment variables, loads a native library
    (libgomp's ABI) or downloads anything: an application that embeds gma inherits none of it."""
    offenders = []
    for path in sorted((REPO / "gma").rglob("*.py")):
        rel = path.relative_to(REPO).as_posix()
        if rel.startswith(APPLICATION):
            continue
        offenders += [f"{rel} {what}" for what in _process_changes(ast.parse(path.read_text(), rel))]
    assert not offenders, "\n".join(offenders)


def test_the_process_check_finds_what_it_looks_for():
    code = ("import os, ctypes\nfrom urllib.request import urlopen\nos.environ['A'] = '1'\n"
            "os.environ.setdefault('B', '2')\nos.putenv('C', '3')\ndel os.environ['A']\n"
            "ctypes.CDLL('libgomp.so.1').GOMP_parallel_start\nx = 'GOMP_parallel_end'\nos.environ.get('D')\n")
    found = sorted(_process_changes(ast.parse(code)))
    assert found == ["line 2: imports urllib.request", "line 3: writes os.environ", "line 4: os.environ.setdefault",
                     "line 5: putenv", "line 6: writes os.environ", "line 7: CDLL", "line 8: libgomp's ABI"], found
