"""Ray itself, kept light: the one-line error when the optional extra is missing, and what workers need to
import this GMA. Nothing here imports torch, so ``gma batch`` without Ray fails in a fraction of a second."""

from __future__ import annotations

import os
from pathlib import Path

import gma
from gma.core.errors import InputError

__all__ = ["import_ray", "runtime_env"]


def import_ray():
    """Ray, or a one-line error saying how to get it (it is the optional extra ``gma[cluster]``)."""
    try:
        import ray
    except ImportError:
        raise InputError("gma batch needs Ray: pip install 'gma[cluster]' (or pip install 'ray>=2.9')") from None
    return ray


def runtime_env() -> dict:
    """What Ray workers need to import this GMA. An installed GMA is found by every worker already; a
    checkout (``gma/`` next to ``pyproject.toml``) is put on the workers' PYTHONPATH, which reaches
    workers on other machines only when the checkout lies at the same path there (a shared filesystem)."""
    root = Path(gma.__file__).resolve().parents[1]
    if not (root / "pyproject.toml").is_file():
        return {}
    paths = [str(root)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]
    return {"env_vars": {"PYTHONPATH": os.pathsep.join(dict.fromkeys(paths))}}
