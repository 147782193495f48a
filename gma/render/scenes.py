"""Built-in surfel scenes for tests, benchmarks and the demo (no files needed)."""

from __future__ import annotations

import math

import numpy as np

from gma.core.camera import Camera


def random_scene(n: int, seed: int = 0, channels: int = 3, depth: float = 4.0, spread: float = 1.0,
                 scale_range=(0.02, 0.2)) -> dict[str, np.ndarray]:
    """``n`` surfels in a cube of half-size ``spread`` centred ``depth`` in front of the origin."""
    rng = np.random.default_rng(seed)
    means = rng.uniform(-spread, spread, (n, 3))
    means[:, 2] += depth
    quats = rng.normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True) + 1e-12
    return {
        "means": means.astype(np.float32),
        "quats": quats.astype(np.float32),
        "scales": rng.uniform(*scale_range, (n, 2)).astype(np.float32),
        "opacities": rng.uniform(0.05, 1.0, n).astype(np.float32),
        "colors": rng.uniform(0, 1, (n, channels)).astype(np.float32),
    }


def _frame_from_normal(normals: np.ndarray) -> np.ndarray:
    """Quaternions (w, x, y, z) whose third rotated axis is ``normals`` [N, 3]."""
    z = np.array([0.0, 0.0, 1.0])
    n = normals / np.linalg.norm(normals, axis=1, keepdims=True)
    axis = np.cross(z, n)
    s = np.linalg.norm(axis, axis=1)
    c = n @ z
    angle = np.arctan2(s, c)
    axis = np.where(s[:, None] > 1e-9, axis / np.maximum(s, 1e-12)[:, None], np.array([1.0, 0.0, 0.0]))
    half = angle / 2
    return np.concatenate([np.cos(half)[:, None], axis * np.sin(half)[:, None]], 1)


def avatar_like_scene(n: int, seed: int = 0) -> dict[str, np.ndarray]:
    """``n`` surfels tangent to a body-sized closed surface (torso, head, two arms, two legs as
    ellipsoids, 1.75 m tall), sized so that neighbours overlap as on a fitted avatar."""
    rng = np.random.default_rng(seed)
    # (centre, radii) of ellipsoids; y up, metres.
    parts = [((0, 1.25, 0), (0.17, 0.30, 0.11)), ((0, 1.63, 0), (0.10, 0.12, 0.11)),
             ((-0.27, 1.22, 0), (0.05, 0.28, 0.05)), ((0.27, 1.22, 0), (0.05, 0.28, 0.05)),
             ((-0.10, 0.47, 0), (0.07, 0.45, 0.07)), ((0.10, 0.47, 0), (0.07, 0.45, 0.07))]
    centres = np.array([p[0] for p in parts], float)
    radii = np.array([p[1] for p in parts], float)
    # Area of each ellipsoid (Thomsen's approximation) decides how many surfels it gets.
    a, b, c = radii.T ** 1.6
    area = 4 * math.pi * ((a * b + a * c + b * c) / 3) ** (1 / 1.6)
    part = rng.choice(len(parts), size=n, p=area / area.sum())
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    means = centres[part] + d * radii[part]
    normals = d / radii[part]  # gradient of the implicit ellipsoid
    spacing = math.sqrt(area.sum() / n)
    scales = spacing * rng.uniform(0.5, 0.9, (n, 2))
    # Spin each surfel about its normal so that the in-plane axes vary.
    quats = _frame_from_normal(normals)
    spin = rng.uniform(0, math.pi, n)
    spin_q = np.stack([np.cos(spin / 2), np.zeros(n), np.zeros(n), np.sin(spin / 2)], 1)
    quats = quat_multiply(quats, spin_q)
    u = means[:, 1:2] * 6.0
    colors = 0.5 + 0.4 * np.concatenate([np.sin(u + part[:, None]), np.cos(u * 1.7), np.sin(3 * d[:, :1])], 1)
    return {
        "means": means.astype(np.float32),
        "quats": quats.astype(np.float32),
        "scales": scales.astype(np.float32),
        "opacities": rng.uniform(0.7, 1.0, n).astype(np.float32),
        "colors": colors.astype(np.float32),
    }


def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product of (w, x, y, z) quaternions, [N, 4] each."""
    w1, x1, y1, z1 = a.T
    w2, x2, y2, z2 = b.T
    return np.stack([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2], 1)


def avatar_camera(width: int = 512, height: int = 512, azimuth_deg: float = 0.0, distance: float = 2.6) -> Camera:
    """A camera orbiting the avatar-like scene at hip-to-chest height, looking at its middle."""
    a = math.radians(azimuth_deg)
    eye = (distance * math.sin(a), 1.0, distance * math.cos(a))
    return Camera.look_at(eye, (0.0, 0.9, 0.0), up=(0.0, 1.0, 0.0), fov_y_deg=45.0, width=width, height=height)
