"""``load_body(name)``: the one place that maps a body model name to its backend."""

from __future__ import annotations

import os
from pathlib import Path

from gma.body.base import BodyModel

__all__ = ["BODY_MODELS", "load_body"]

BODY_MODELS = ("anny", "smplx")


def load_body(name: str = "anny", smplx_dir: str | Path | None = None, **kwargs) -> BodyModel:
    """The body model ``name``: "anny" (default, free, created once per process and cached) or "smplx"
    (model files from ``smplx_dir`` or ``$GMA_SMPLX_DIR``; ``gender`` etc. in ``kwargs``)."""
    if name == "anny":
        from gma.body.anny_body import AnnyBody

        return AnnyBody.create(**kwargs)
    if name == "smplx":
        from gma.body.smplx_body import SmplxBody

        return SmplxBody.load(smplx_dir or os.environ.get("GMA_SMPLX_DIR"), **kwargs)
    raise ValueError(f"unknown body model {name!r}; choose one of {', '.join(BODY_MODELS)}")
