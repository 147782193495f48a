"""Shared helpers for the renderer tests: scenes as torch tensors and image comparison with stated
tolerances."""

from __future__ import annotations

import numpy as np
import torch

from gma.core.camera import Camera
from gma.render.scenes import random_scene

# GPU and reference compute the same float32 formulas in a different order (fused multiply-adds,
# exp/div implementations), so values agree to a few ulps of the quantities involved: 2e-4 absolute
# covers depth (values up to ~6, accumulated over tens of surfels) with margin. A pixel whose alpha
# sits within rounding of the 1/255 skip threshold, or whose transmittance sits within rounding of
# the 1e-4 stop, can take the other branch: that moves the pixel by up to one surfel's contribution
# at alpha ~ 1/255 (<= 1/255 * |value|). We allow at most 0.2% of values to differ by more than 2e-4,
# and none by more than 2/255 * max|value| + 2e-4.
ATOL = 2e-4
OUTLIER_FRACTION = 2e-3


def assert_image_close(name: str, got: np.ndarray, want: np.ndarray, scale: float = 1.0) -> None:
    assert got.shape == want.shape, f"{name}: shape {got.shape} != {want.shape}"
    diff = np.abs(got - want)
    outliers = diff > ATOL
    frac = float(outliers.mean()) if diff.size else 0.0
    hard = 2.0 / 255.0 * scale + ATOL
    assert frac <= OUTLIER_FRACTION, f"{name}: {frac:.4%} values differ by > {ATOL} (max {diff.max():.3g})"
    assert diff.size == 0 or diff.max() <= hard, f"{name}: max difference {diff.max():.3g} > {hard:.3g}"


def default_camera(width: int, height: int) -> Camera:
    f = 0.8 * max(width, height)
    K = np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], np.float32)
    return Camera(np.eye(4, dtype=np.float32), K, width, height)


def torch_scene(n: int, seed: int = 0, channels: int = 3, **kw) -> dict[str, torch.Tensor]:
    return {k: torch.from_numpy(v) for k, v in random_scene(n, seed, channels, **kw).items()}


def special_surfels(seed: int = 1) -> dict[str, torch.Tensor]:
    """Surfels that stress the edge cases: behind the camera, on the near plane, edge-on, tiny, huge
    (its circle crosses the camera plane), zero-scale, and transparent below 1/255."""
    rng = np.random.default_rng(seed)
    base = random_scene(40, seed)
    means = [[0.1, 0.0, -2.0], [0.0, 0.1, 0.005], [0.2, 0.1, 3.0], [-0.2, 0.0, 3.0], [0.0, 0.0, 2.0],
             [0.3, -0.2, 3.5], [0.0, 0.2, 2.5]]
    quats = [[1, 0, 0, 0], [1, 0, 0, 0], [0.7071, 0.7071, 0, 0], [0.7071, 0, 0.7071, 0], [1, 0, 0, 0],
             [1, 0, 0, 0], [1, 0, 0, 0]]
    scales = [[0.5, 0.5], [0.2, 0.2], [0.3, 0.05], [0.2, 0.2], [5.0, 5.0], [1e-4, 1e-4], [0.0, 0.0]]
    opac = [0.9, 0.9, 0.9, 0.9, 0.3, 0.9, 0.8]
    k = len(means)
    out = {
        "means": np.concatenate([base["means"], np.array(means, np.float32)]),
        "quats": np.concatenate([base["quats"], np.array(quats, np.float32)]),
        "scales": np.concatenate([base["scales"], np.array(scales, np.float32)]),
        "opacities": np.concatenate([base["opacities"], np.array(opac, np.float32)]),
        "colors": np.concatenate([base["colors"], rng.uniform(0, 1, (k, 3)).astype(np.float32)]),
    }
    out["opacities"][3] = 0.002  # below 1/255: never visible
    return {key: torch.from_numpy(np.ascontiguousarray(v)) for key, v in out.items()}
