"""Run several benchmark scripts one after another in this one process, as ``python SCRIPT ARGS`` would
run each, so that Python, torch, the body model and the GPU device start once for all of them
(tests/test_benchmarks.py's smoke runs). Each script runs as ``__main__`` in its own folder with its own
``sys.argv``; its exit status, printed output and any traceback go to ``RESULTS/<script>.json``.

    python tests/smoke_runner.py RESULTS SPEC.json     # SPEC: [[script path, folder, [args...]], ...]
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import runpy
import sys
import traceback
from pathlib import Path


def fresh_torch_state(threads: int | None) -> None:
    """Undo what a script may have set process-wide in torch (a script may switch gradients off for
    itself, or set its thread count), as a new process would start."""
    torch = sys.modules.get("torch")
    if torch is not None:
        torch.set_grad_enabled(True)
        if threads is not None:
            torch.set_num_threads(threads)


def run_one(script: Path, folder: Path, args: list[str]) -> dict:
    """Run ``script`` with ``args`` in ``folder``: {"returncode", "stdout", "stderr"} (a traceback in
    stderr and return code 1 when it raised)."""
    out, err = io.StringIO(), io.StringIO()
    argv, cwd = sys.argv, os.getcwd()
    code = 0
    sys.argv = [str(script), *args]
    os.chdir(folder)
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                runpy.run_path(str(script), run_name="__main__")
            except SystemExit as exc:  # sys.exit(main()): None and 0 are success
                code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
                if not isinstance(exc.code, int | None):
                    print(exc.code, file=sys.stderr)
            except Exception:
                traceback.print_exc()
                code = 1
    finally:
        sys.argv = argv
        os.chdir(cwd)
    return {"returncode": code, "stdout": out.getvalue(), "stderr": err.getvalue()}


def main() -> int:
    results, spec = Path(sys.argv[1]), json.loads(Path(sys.argv[2]).read_text())
    try:  # torch's own thread count, before any script sets it (the scripts import torch anyway)
        import torch

        threads = torch.get_num_threads()
    except ImportError:
        threads = None
    for script, folder, args in spec:
        fresh_torch_state(threads)
        script = Path(script)
        sys.path.insert(0, str(script.parent))  # as ``python SCRIPT`` puts the script's folder first
        try:
            result = run_one(script, Path(folder), args)
        finally:
            sys.path.remove(str(script.parent))
        (results / f"{script.name}.json").write_text(json.dumps(result))
    return 0


if __name__ == "__main__":
    sys.exit(main())
