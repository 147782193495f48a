"""The standard scene the renderer benchmarks time: ``n`` random surfels in a 1 m box 3 m in front of a
512 x 512 pinhole camera, seed 0. Other CPU splatting renderers were timed on the same statistics, so its
figures compare with theirs; the arrays are the same on every machine and every run.

Scene: means uniform in an axis-aligned box of side 1 centred at (0, 0, 3); scales log-uniform in
[0.003, 0.02]; unit quaternions uniform on the sphere (w, x, y, z); opacities uniform in [0.3, 0.9];
RGB colours uniform in [0, 1]. The camera frame is the world frame (OpenCV: x right, y down, z forward,
view matrix = identity), fx = fy = 600, cx = cy = 256; background black. A 2DGS renderer takes the first
two scales (``scales_2d`` has the third set to 0).
"""

from __future__ import annotations

import numpy as np

WIDTH = HEIGHT = 512
FOCAL = 600.0
BOX_SIDE = 1.0
BOX_CENTRE = (0.0, 0.0, 3.0)
SCALE_RANGE = (0.003, 0.02)
OPACITY_RANGE = (0.3, 0.9)
SEED = 0


def camera() -> tuple[np.ndarray, np.ndarray]:
    """(viewmat [4, 4] world-to-camera, K [3, 3]), float32."""
    K = np.array([[FOCAL, 0.0, WIDTH / 2], [0.0, FOCAL, HEIGHT / 2], [0.0, 0.0, 1.0]], np.float32)
    return np.eye(4, dtype=np.float32), K


def make_workload(n: int, seed: int = SEED) -> dict[str, np.ndarray]:
    """The scene of ``n`` surfels as float32 arrays: means [n, 3], scales [n, 3], scales_2d [n, 3] (third
    column 0), quats [n, 4] (w, x, y, z), opacities [n], colors [n, 3], viewmat [4, 4], K [3, 3]. The draws
    come in this order from one generator, so a scene of ``n`` surfels is the same wherever it is made."""
    rng = np.random.default_rng(seed)
    half = BOX_SIDE / 2
    means = rng.uniform(-half, half, size=(n, 3)) + np.array(BOX_CENTRE)
    log_lo, log_hi = np.log(SCALE_RANGE)
    scales = np.exp(rng.uniform(log_lo, log_hi, size=(n, 3)))
    quats = rng.standard_normal(size=(n, 4))
    quats /= np.linalg.norm(quats, axis=1, keepdims=True)  # a normalised Gaussian draw is uniform on S^3
    opacities = rng.uniform(*OPACITY_RANGE, size=(n,))
    colors = rng.uniform(0.0, 1.0, size=(n, 3))
    scales_2d = scales.copy()
    scales_2d[:, 2] = 0.0
    viewmat, K = camera()
    arrays = {"means": means, "scales": scales, "scales_2d": scales_2d, "quats": quats, "opacities": opacities,
              "colors": colors}
    scene = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in arrays.items()}
    return dict(scene, viewmat=viewmat, K=K)
