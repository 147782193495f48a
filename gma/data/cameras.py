"""Cameras of a sequence (``cameras.json``): OpenCV pinhole, world→camera 4×4 ``w2c`` (x right, y down,
z forward), intrinsics ``K`` 3×3 in pixels, image ``width``×``height``. Either one camera for all frames
or one per frame (``K`` [T, 3, 3], ``w2c`` [T, 4, 4])."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.atomic import atomic_write_json
from gma.core.camera import look_at_w2c as look_at  # one camera convention for the project
from gma.core.camera import parse_camera_json, read_camera_json, validate_camera_arrays

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
    """Raise ``InputError`` naming ``source`` for bad sizes, shapes, frame counts or values (the rules of
    :func:`gma.core.camera.validate_camera_arrays`)."""
    validate_camera_arrays(cams.width, cams.height, cams.K, cams.w2c, source, num_frames)


def load_cameras(path: str | os.PathLike, num_frames: int | None = None) -> Cameras:
    """Read and validate ``cameras.json``; a single camera comes back with T = 1."""
    width, height, K, w2c = parse_camera_json(read_camera_json(path), str(Path(path)), num_frames)
    return Cameras(width, height, K, w2c)


def save_cameras(path: str | os.PathLike, cams: Cameras) -> None:
    validate_cameras(cams, str(path))
    atomic_write_json(path, cams.to_json())


