"""Cameras of a sequence (``cameras.json``): OpenCV pinhole, world→camera 4×4 ``w2c`` (x right, y down,
z forward), intrinsics ``K`` 3×3 in pixels, image ``width``×``height``. Either one camera for all frames
or one per frame (``K`` [T, 3, 3], ``w2c`` [T, 4, 4])."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.atomic import atomic_write_json
from gma.core.camera import look_at_w2c as look_at  # one camera convention for the project

__all__ = ["Cameras", "load_cameras", "save_cameras", "look_at"]


@dataclass
class Cameras:
    """``K`` [T, 3, 3] and ``w2c`` [T, 4, 4] float64 (T = 1 for a static camera), image size in pixels."""

    width: int
    height: int
    K: np.ndarray
    w2c: np.ndarray

    @property
    def static(self) -> bool:
        return self.K.shape[0] == 1 and self.w2c.shape[0] == 1

    def frame(self, i: int) -> tuple[np.ndarray, np.ndarray]:
        """(K [3, 3], w2c [4, 4]) of frame ``i``."""
        k = self.K[0 if self.K.shape[0] == 1 else i]
        w = self.w2c[0 if self.w2c.shape[0] == 1 else i]
        return k, w

    def subset(self, indices) -> Cameras:
        idx = np.asarray(indices, dtype=np.int64)
        k = self.K if self.K.shape[0] == 1 else self.K[idx]
        w = self.w2c if self.w2c.shape[0] == 1 else self.w2c[idx]
        return Cameras(self.width, self.height, k, w)

    def to_json(self) -> dict:
        def squeeze(a):
            return a[0].tolist() if a.shape[0] == 1 else a.tolist()

        return {"width": int(self.width), "height": int(self.height),
                "K": squeeze(self.K), "w2c": squeeze(self.w2c)}


def validate_cameras(cams: Cameras, source: str, num_frames: int | None = None) -> None:
    """Raise ``ValueError`` naming ``source`` for bad sizes, shapes, frame counts or values."""
    for name in ("width", "height"):
        v = getattr(cams, name)
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v <= 0:
            raise ValueError(f"{source}: {name!r} must be a positive integer, got {v!r}")
    for name, shape in (("K", (3, 3)), ("w2c", (4, 4))):
        a = getattr(cams, name)
        if a.ndim != 3 or a.shape[1:] != shape:
            got = list(a.shape)[1:] if a.ndim == 3 else list(a.shape)
            raise ValueError(f"{source}: {name!r} has shape {got}"
                             f" per frame, expected {list(shape)} or [T, {shape[0]}, {shape[1]}]")
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{source}: {name!r} holds a non-finite value")
        if num_frames is not None and a.shape[0] not in (1, num_frames):
            raise ValueError(f"{source}: {name!r} has {a.shape[0]} per-frame entries but the sequence has "
                             f"{num_frames} frames")
    if np.any(cams.K[:, 0, 0] <= 0) or np.any(cams.K[:, 1, 1] <= 0):
        raise ValueError(f"{source}: 'K' focal lengths must be positive")
    if not np.allclose(cams.K[:, 2], [0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError(f"{source}: 'K' last row must be [0, 0, 1]")
    if not np.allclose(cams.w2c[:, 3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise ValueError(f"{source}: 'w2c' last row must be [0, 0, 0, 1]")
    r = cams.w2c[:, :3, :3]
    err = np.abs(r @ np.swapaxes(r, 1, 2) - np.eye(3)).max()
    if err > 1e-4 or np.any(np.linalg.det(r) < 0):
        raise ValueError(f"{source}: 'w2c' rotation is not a proper rotation (orthonormality error "
                         f"{err:.2g}); is it camera-to-world, or scaled?")


def _as_stack(value, shape: tuple[int, int], name: str, source: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f"{source}: {name!r} is not a numeric array ({exc})") from exc
    if a.shape == shape:
        a = a[None]
    return a


def load_cameras(path: str | os.PathLike, num_frames: int | None = None) -> Cameras:
    """Read and validate ``cameras.json``; a single camera comes back with T = 1."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: camera file not found")
    try:
        raw = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: expected a JSON object with width, height, K, w2c")
    for key in ("width", "height", "K", "w2c"):
        if key not in raw:
            raise ValueError(f"{path}: missing {key!r}")
    cams = Cameras(raw["width"], raw["height"], _as_stack(raw["K"], (3, 3), "K", str(path)),
                   _as_stack(raw["w2c"], (4, 4), "w2c", str(path)))
    validate_cameras(cams, str(path), num_frames)
    return cams


def save_cameras(path: str | os.PathLike, cams: Cameras) -> None:
    validate_cameras(cams, str(path))
    atomic_write_json(path, cams.to_json())


