"""Argument checks for the public render functions: every message names the argument and the problem."""

from __future__ import annotations

import numpy as np
import torch

MAX_CHANNELS = 64


def as_float_tensor(name: str, value) -> torch.Tensor:
    if isinstance(value, np.ndarray):
        value = torch.from_numpy(value)
    if not isinstance(value, torch.Tensor):
        raise TypeError(f"{name} must be a torch tensor, got {type(value).__name__}")
    if not value.is_floating_point():
        raise TypeError(f"{name} must be a floating-point tensor, got dtype {value.dtype}")
    return value


def check_shape(name: str, t: torch.Tensor, shape: tuple) -> None:
    """``shape`` entries are ints or None (any size)."""
    ok = t.dim() == len(shape) and all(s is None or s == d for s, d in zip(shape, t.shape))
    if not ok:
        want = "[" + ", ".join("*" if s is None else str(s) for s in shape) + "]"
        raise ValueError(f"{name} must have shape {want}, got {list(t.shape)}")


def check_finite(name: str, t: torch.Tensor) -> None:
    bad = ~torch.isfinite(t.detach())
    if bool(bad.any()):
        first = torch.nonzero(bad)[0].tolist()
        raise ValueError(f"{name} holds {int(bad.sum())} non-finite values (NaN or inf), first at index {first}")


def check_surfels(means, quats, scales, opacities, colors):
    """Validate surfel tensors; returns them as tensors (opacities [N], others 2-D)."""
    means = as_float_tensor("means", means)
    quats = as_float_tensor("quats", quats)
    scales = as_float_tensor("scales", scales)
    opacities = as_float_tensor("opacities", opacities)
    colors = as_float_tensor("colors", colors)
    check_shape("means", means, (None, 3))
    n = means.shape[0]
    check_shape("quats", quats, (n, 4))
    check_shape("scales", scales, (n, 2))
    if opacities.dim() == 2 and opacities.shape[1] == 1:
        opacities = opacities[:, 0]
    check_shape("opacities", opacities, (n,))
    check_shape("colors", colors, (n, None))
    if not 1 <= colors.shape[1] <= MAX_CHANNELS:
        raise ValueError(f"colors must have 1 to {MAX_CHANNELS} channels, got {colors.shape[1]}")
    devices = {t.device for t in (means, quats, scales, opacities, colors)}
    if len(devices) > 1:
        raise ValueError(f"surfel tensors are on different devices: {sorted(map(str, devices))}")
    for name, t in (("means", means), ("quats", quats), ("scales", scales), ("opacities", opacities),
                    ("colors", colors)):
        check_finite(name, t)
    if n:
        if bool((quats.detach().norm(dim=1) == 0).any()):
            raise ValueError("quats has zero-length rows; a rotation quaternion must be non-zero")
        if bool((scales.detach() < 0).any()):
            raise ValueError("scales must be >= 0 (already activated, e.g. exp of log-scales)")
        o = opacities.detach()
        if bool(((o < 0) | (o > 1)).any()):
            raise ValueError("opacities must lie in [0, 1] (already activated, e.g. sigmoid of logits)")
    return means, quats, scales, opacities, colors


def check_camera(viewmat, K, width, height):
    viewmat = as_float_tensor("viewmat", viewmat)
    K = as_float_tensor("K", K)
    check_shape("viewmat", viewmat, (4, 4))
    check_shape("K", K, (3, 3))
    check_finite("viewmat", viewmat)
    check_finite("K", K)
    for name, v in (("width", width), ("height", height)):
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v <= 0:
            raise ValueError(f"{name} must be a positive integer, got {v!r}")
        if v > 16384:
            raise ValueError(f"{name} = {v} exceeds the supported maximum of 16384 pixels")
    return viewmat, K, int(width), int(height)


def check_background(background, channels: int):
    if background is None:
        return None
    background = as_float_tensor("background", background)
    check_shape("background", background, (channels,))
    check_finite("background", background)
    return background
