"""Writing rendered images: float [H, W, C] in [0, 1] to 8-bit PNG, atomically."""

from __future__ import annotations

from pathlib import Path

import imageio.v3 as iio
import numpy as np

from gma.core.atomic import atomic_file


def to_uint8(image: np.ndarray) -> np.ndarray:
    return (np.clip(np.asarray(image, np.float32), 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def save_png(path: str | Path, image: np.ndarray) -> Path:
    """Write ``image`` ([H, W, 1|3|4] float in [0, 1] or uint8) to ``path`` atomically."""
    path = Path(path)
    data = image if image.dtype == np.uint8 else to_uint8(image)
    if data.ndim == 3 and data.shape[2] == 1:
        data = data[..., 0]
    with atomic_file(path) as tmp:
        iio.imwrite(tmp, data, extension=".png")
    return path
