"""Pinhole cameras in the OpenCV convention (x right, y down, z forward) and their JSON form.

The JSON form is the sequence format's ``cameras.json``: ``width`` and ``height`` in pixels, intrinsics
``K`` 3x3 in pixels and world->camera ``w2c`` 4x4, either one camera for all frames or one per frame
(``K`` [T, 3, 3], ``w2c`` [T, 4, 4]). :func:`parse_camera_json` is its only parser: a sequence's cameras
(:func:`gma.data.cameras.load_cameras`) and a single ``--camera`` file (:meth:`Camera.load`) follow the
same rules and give the same messages.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.errors import InputError, MissingFileError

__all__ = ["Camera", "look_at_w2c", "parse_camera_json", "projection_matrix", "read_camera_json",
           "validate_camera_arrays"]

_KEYS = ("width", "height", "K", "w2c")


def read_camera_json(path: str | os.PathLike, keys: str = ", ".join(_KEYS)) -> dict:
    """The JSON object of a camera file, not validated yet (:func:`parse_camera_json` does that for
    extrinsic cameras; ``keys`` names what the object should hold, for the message when it is not one)."""
    path = Path(path)
    if not path.is_file():
        raise MissingFileError(f"{path}: camera file not found")
    try:
        raw = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(raw, dict):
        raise InputError(f"{path}: expected a JSON object with {keys}")
    return raw


def parse_camera_json(raw: dict, source: str, num_frames: int | None = None
                      ) -> tuple[int, int, np.ndarray, np.ndarray]:
    """(width, height, K [T, 3, 3], w2c [T, 4, 4] float64) of a camera JSON object, validated by
    :func:`validate_camera_arrays`; a single camera comes back with T = 1. ``source`` names the file in
    the messages (:class:`InputError`)."""
    if not isinstance(raw, dict):
        raise InputError(f"{source}: expected a JSON object with {', '.join(_KEYS)}")
    for key in _KEYS:
        if key not in raw:
            raise InputError(f"{source}: missing {key!r}")
    K = _as_stack(raw["K"], (3, 3), "K", source)
    w2c = _as_stack(raw["w2c"], (4, 4), "w2c", source)
    validate_camera_arrays(raw["width"], raw["height"], K, w2c, source, num_frames)
    return int(raw["width"]), int(raw["height"]), K, w2c


def _as_stack(value, shape: tuple[int, int], name: str, source: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"{source}: {name!r} is not a numeric array ({exc})") from None
    return a[None] if a.shape == shape else a


def validate_camera_arrays(width, height, K: np.ndarray, w2c: np.ndarray, source: str,
                           num_frames: int | None = None) -> None:
    """Raise :class:`InputError` naming ``source`` for a size that is not a positive integer, ``K`` /
    ``w2c`` not [T, 3, 3] / [T, 4, 4], non-finite values, a per-frame count other than 1 or
    ``num_frames``, focal lengths not positive, wrong last rows, or a ``w2c`` rotation that is not one
    (a camera-to-world matrix, or a scaled one)."""
    for name, v in (("width", width), ("height", height)):
        if not isinstance(v, (int, np.integer)) or isinstance(v, bool) or v <= 0:
            raise InputError(f"{source}: {name!r} must be a positive integer, got {v!r}")
    for name, a, shape in (("K", K, (3, 3)), ("w2c", w2c, (4, 4))):
        if a.ndim != 3 or a.shape[1:] != shape:
            got = list(a.shape)[1:] if a.ndim == 3 else list(a.shape)
            raise InputError(f"{source}: {name!r} has shape {got}"
                             f" per frame, expected {list(shape)} or [T, {shape[0]}, {shape[1]}]")
        if not np.all(np.isfinite(a)):
            raise InputError(f"{source}: {name!r} holds a non-finite value")
        if num_frames is not None and a.shape[0] not in (1, num_frames):
            raise InputError(f"{source}: {name!r} has {a.shape[0]} per-frame entries but the sequence has "
                             f"{num_frames} frames")
    if np.any(K[:, 0, 0] <= 0) or np.any(K[:, 1, 1] <= 0):
        raise InputError(f"{source}: 'K' focal lengths must be positive")
    if not np.allclose(K[:, 2], [0.0, 0.0, 1.0], atol=1e-6):
        raise InputError(f"{source}: 'K' last row must be [0, 0, 1]")
    if not np.allclose(w2c[:, 3], [0.0, 0.0, 0.0, 1.0], atol=1e-6):
        raise InputError(f"{source}: 'w2c' last row must be [0, 0, 0, 1]")
    r = w2c[:, :3, :3]
    err = np.abs(r @ np.swapaxes(r, 1, 2) - np.eye(3)).max()
    if err > 1e-4 or np.any(np.linalg.det(r) < 0):
        raise InputError(f"{source}: 'w2c' rotation is not a proper rotation (orthonormality error "
                         f"{err:.2g}); is it camera-to-world, or scaled?")


def look_at_w2c(eye, target, up=(0.0, 1.0, 0.0)) -> np.ndarray:
    """OpenCV world->camera 4x4 (float64) for a camera at ``eye`` looking at ``target``, with world ``up``
    shown upwards in the image (the camera's y axis points down, so it is -up projected)."""
    eye = np.asarray(eye, np.float64)
    forward = np.asarray(target, np.float64) - eye
    forward /= np.linalg.norm(forward)
    right = np.cross(forward, np.asarray(up, np.float64))
    if np.linalg.norm(right) < 1e-8:
        raise ValueError("look_at: 'up' is parallel to the viewing direction")
    right /= np.linalg.norm(right)
    down = np.cross(forward, right)
    R = np.stack([right, down, forward])  # rows: camera axes in world coordinates
    view = np.eye(4)
    view[:3, :3] = R
    view[:3, 3] = -R @ eye
    return view


@dataclass(frozen=True)
class Camera:
    """``viewmat`` [4, 4] world->camera, ``K`` [3, 3] intrinsics in pixels, image ``width`` x ``height``."""

    viewmat: np.ndarray
    K: np.ndarray
    width: int
    height: int

    @staticmethod
    def look_at(eye, target, up=(0.0, -1.0, 0.0), fov_y_deg: float = 40.0, width: int = 512,
                height: int = 512) -> Camera:
        """A camera at ``eye`` looking at ``target``; ``up`` is the world direction shown upwards.

        OpenCV's y axis points down in the image, so the camera's y axis is ``-up`` projected.
        """
        view = look_at_w2c(eye, target, up)
        f = 0.5 * height / math.tan(math.radians(fov_y_deg) / 2)
        K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]])
        return Camera(view.astype(np.float32), K.astype(np.float32), int(width), int(height))

    @property
    def eye(self) -> np.ndarray:
        """[3] camera centre in world coordinates (float64)."""
        R, t = self.viewmat[:3, :3].astype(np.float64), self.viewmat[:3, 3].astype(np.float64)
        return -R.T @ t

    def resized(self, width: int, height: int) -> Camera:
        """The same view on a ``width`` x ``height`` image: the intrinsics scale with the image, so that its
        edges (and every point between them) map to the same rays."""
        if (width, height) == (self.width, self.height):
            return self
        s = np.array([width / self.width, height / self.height, 1.0], np.float32)[:, None]
        return Camera(self.viewmat, (self.K * s).astype(np.float32), int(width), int(height))

    def project(self, points) -> tuple[np.ndarray, np.ndarray]:
        """World points [N, 3] -> (pixels [N, 2], camera depth z [N]), in float64. Points at z = 0 give
        inf/nan pixels, without a warning."""
        R, t = self.viewmat[:3, :3].astype(np.float64), self.viewmat[:3, 3].astype(np.float64)
        pc = np.asarray(points, np.float64) @ R.T + t
        uvw = pc @ self.K.astype(np.float64).T
        with np.errstate(divide="ignore", invalid="ignore"):
            return uvw[:, :2] / uvw[:, 2:3], pc[:, 2]

    def to_json(self) -> dict:
        return {"width": self.width, "height": self.height, "K": self.K.tolist(), "w2c": self.viewmat.tolist()}

    @staticmethod
    def from_json(data: dict, source: str = "camera") -> Camera:
        """One camera from its JSON object (:func:`parse_camera_json`'s rules); a per-frame list is refused."""
        width, height, K, w2c = parse_camera_json(data, source)
        if K.shape[0] != 1 or w2c.shape[0] != 1:
            raise InputError(f"{source}: holds {max(K.shape[0], w2c.shape[0])} per-frame cameras; "
                             "one camera expected")
        return Camera(w2c[0].astype(np.float32), K[0].astype(np.float32), width, height)

    @staticmethod
    def load(path: str | os.PathLike) -> Camera:
        """One camera from a JSON file (:meth:`from_json`)."""
        return Camera.from_json(read_camera_json(path), str(path))


def projection_matrix(
    K: np.ndarray, width: int, height: int, near: float = 0.05, far: float = 100.0
) -> np.ndarray:
    """4×4 map from OpenCV camera space (x right, y down, z forward; metres) to wgpu clip space for an
    image of ``width``×``height`` pixels, so that the projection ``K @ x`` lands on framebuffer pixel
    coordinates (pixel centres at +0.5) and depth ``near``..``far`` maps to 0..1."""
    fx, s, cx = K[0]
    fy, cy = K[1, 1], K[1, 2]
    P = np.zeros((4, 4))
    P[0] = [2 * fx / width, 2 * s / width, 2 * cx / width - 1, 0]
    P[1] = [0, -2 * fy / height, 1 - 2 * cy / height, 0]
    P[2] = [0, 0, far / (far - near), -far * near / (far - near)]
    P[3] = [0, 0, 1, 0]
    return P
