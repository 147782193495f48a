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


def host_array(t: torch.Tensor) -> np.ndarray:
    """``t`` as a C-contiguous float32 numpy array on the host: a view when it already is one, otherwise
    one numpy copy. Checks and conversions of the public render call run in numpy, single-threaded: torch's
    OpenMP workers spin-wait between parallel ops, and next to lavapipe's threads on a busy small CPU
    each such op waits for cores far longer than it computes."""
    t = t.detach()
    if t.device.type != "cpu":
        t = t.cpu()
    if t.dtype not in (torch.float32, torch.float64, torch.float16):
        t = t.float()  # numpy has no bfloat16
    return np.ascontiguousarray(t.numpy(), dtype=np.float32)


def check_finite(name: str, a: np.ndarray) -> None:
    # One vectorised pass (cheaper than a float64 sum, whose finiteness says the same); only a bad
    # array is searched value by value, to name the first.
    bad = ~np.isfinite(a)
    if bad.any():
        first = np.argwhere(bad)[0].tolist()
        raise ValueError(f"{name} holds {int(bad.sum())} non-finite values (NaN or inf), first at index {first}")


def _zero_length_rows(q: np.ndarray) -> bool:
    """Whether some row of ``q`` [N, 4] (float32, C-contiguous) has |q|^2 == 0 in float32, as
    np.linalg.norm squares it. Only rows whose four components are all below 1e-18 in size can (a
    larger one squares to >= 1e-36, which float32 holds): those are found through the row's four
    booleans read as one 32-bit word, and checked exactly (far cheaper than an einsum over every
    row)."""
    tiny = np.ascontiguousarray(np.abs(q) < 1e-18).view(np.uint32).reshape(-1)
    candidates = tiny == 0x01010101
    if not candidates.any():
        return False
    rows = q[candidates]
    return bool((np.einsum("ij,ij->i", rows, rows) == 0).any())


def check_surfels(means, quats, scales, opacities, colors, values: bool = True):
    """Validate surfel tensors. Returns them as tensors (opacities [N], others 2-D) and their host copies
    (float32 numpy, see :func:`host_array`) in the same order. ``values=False`` checks types and shapes
    only; the caller then runs :func:`check_surfel_values` on the host copies before it uses a result."""
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
    tensors = (means, quats, scales, opacities, colors)
    host = tuple(host_array(t) for t in tensors)
    if values:
        check_surfel_values(host)
    return tensors, host


def check_surfel_values(host) -> None:
    """The value checks of :func:`check_surfels` on its host copies (means, quats, scales, opacities,
    colors as float32 numpy arrays)."""
    for name, a in zip(("means", "quats", "scales", "opacities", "colors"), host):
        check_finite(name, a)
    if len(host[0]):
        q, s, o = host[1], host[2], host[3]
        if _zero_length_rows(q):
            raise ValueError("quats has zero-length rows; a rotation quaternion must be non-zero")
        if (s < 0).any():
            raise ValueError("scales must be >= 0 (already activated, e.g. exp of log-scales)")
        if ((o < 0) | (o > 1)).any():
            raise ValueError("opacities must lie in [0, 1] (already activated, e.g. sigmoid of logits)")


def check_camera(viewmat, K, width, height):
    viewmat = as_float_tensor("viewmat", viewmat)
    K = as_float_tensor("K", K)
    check_shape("viewmat", viewmat, (4, 4))
    check_shape("K", K, (3, 3))
    check_finite("viewmat", host_array(viewmat))
    check_finite("K", host_array(K))
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
    check_finite("background", host_array(background))
    return background
