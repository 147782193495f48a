"""Camera presets from a sequence's ``cameras.json`` (the dataset's views), for the viewer and ``gma render``."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gma.core.camera import Camera
from gma.data.cameras import load_cameras

__all__ = ["sequence_cameras"]


def sequence_cameras(seq_dir: str | Path, limit: int = 16) -> list[Camera]:
    """Up to ``limit`` distinct cameras of a sequence (evenly spaced over its frames when they move)."""
    path = Path(seq_dir)
    path = path / "cameras.json" if path.is_dir() else path
    cams = load_cameras(path)
    t = max(cams.K.shape[0], cams.w2c.shape[0])
    picks = np.unique(np.linspace(0, t - 1, min(limit, t)).round().astype(int))
    out = []
    for i in picks:
        K = cams.K[min(i, cams.K.shape[0] - 1)]
        w2c = cams.w2c[min(i, cams.w2c.shape[0] - 1)]
        out.append(Camera(w2c.astype(np.float32), K.astype(np.float32), int(cams.width), int(cams.height)))
    return out
