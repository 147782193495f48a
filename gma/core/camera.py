"""Pinhole cameras in the OpenCV convention (x right, y down, z forward) and their JSON form."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np


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
        """Parse ``{"width", "height", "K": 3x3, "w2c": 4x4}`` (the sequence format's single-camera form)."""
        try:
            width, height = int(data["width"]), int(data["height"])
            K = np.asarray(data["K"], np.float32)
            view = np.asarray(data.get("w2c", np.eye(4)), np.float32)
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"{source}: expected keys width, height, K (3x3) and w2c (4x4): {exc}") from exc
        if K.shape != (3, 3) or view.shape != (4, 4):
            raise ValueError(f"{source}: K must be 3x3 and w2c 4x4, got {K.shape} and {view.shape}")
        if width <= 0 or height <= 0:
            raise ValueError(f"{source}: width and height must be positive, got {width}x{height}")
        if not (np.isfinite(K).all() and np.isfinite(view).all()):
            raise ValueError(f"{source}: K or w2c holds non-finite values")
        return Camera(view, K, width, height)

    @staticmethod
    def load(path: str | Path) -> Camera:
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"camera file {path} does not exist")
        try:
            data = json.loads(path.read_text())
        except json.JSONDecodeError as exc:
            raise ValueError(f"{path}: not valid JSON ({exc})") from exc
        return Camera.from_json(data, str(path))


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
