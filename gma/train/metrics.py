"""Image metrics in torch: PSNR and SSIM (gaussian window), on [H, W, C] images in [0, 1]."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

__all__ = ["psnr", "ssim"]


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    """Peak signal-to-noise ratio (dB) of two [H, W, C] images in [0, 1]."""
    mse = float(((a - b) ** 2).mean())
    return 99.0 if mse <= 1e-10 else 10 * math.log10(1.0 / mse)


def _window(size: int, sigma: float, channels: int, device) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32, device=device) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    g = g / g.sum()
    return (g[:, None] * g[None, :]).expand(channels, 1, size, size).contiguous()


def ssim(a: torch.Tensor, b: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean structural similarity of [H, W, C] images in [0, 1] (Wang et al. 2004, gaussian 11×11, σ 1.5,
    zero-padded like the 3DGS loss). Differentiable; returns a scalar tensor."""
    c = a.shape[-1]
    x, y = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]  # [1, C, H, W]
    w = _window(window, sigma, c, a.device)
    pad = window // 2

    def blur(t):
        return F.conv2d(t, w, padding=pad, groups=c)

    mx, my = blur(x), blur(y)
    sxx, syy, sxy = blur(x * x) - mx**2, blur(y * y) - my**2, blur(x * y) - mx * my
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx**2 + my**2 + c1) * (sxx + syy + c2))
    return s.mean()
