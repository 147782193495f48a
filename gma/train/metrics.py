"""Image metrics in torch: PSNR and SSIM (gaussian window) on [H, W, C] images in [0, 1], the same inside
the person's bounding box, and mask IoU of a rendered alpha."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

__all__ = ["box_metrics", "mask_iou", "person_box", "psnr", "separable_blur", "ssim", "ssim_map"]


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    """Peak signal-to-noise ratio (dB) of two [H, W, C] images in [0, 1]."""
    mse = float(((a - b) ** 2).mean())
    return 99.0 if mse <= 1e-10 else 10 * math.log10(1.0 / mse)


def _gaussian(size: int, sigma: float, device) -> torch.Tensor:
    x = torch.arange(size, dtype=torch.float32, device=device) - (size - 1) / 2
    g = torch.exp(-(x**2) / (2 * sigma**2))
    return g / g.sum()


def separable_blur(t: torch.Tensor, kernel: torch.Tensor, mode: str = "constant") -> torch.Tensor:
    """``t`` [1, K, H, W], each channel convolved with the odd 1D ``kernel`` along rows and then columns
    (a separable 2D window), padded by ``mode`` of ``F.pad`` ("constant": zeros, "replicate"); same size."""
    k, r = t.shape[1], kernel.numel() // 2
    t = F.conv2d(F.pad(t, (r, r, 0, 0), mode=mode), kernel.view(1, 1, 1, -1).expand(k, 1, 1, -1), groups=k)
    return F.conv2d(F.pad(t, (0, 0, r, r), mode=mode), kernel.view(1, 1, -1, 1).expand(k, 1, -1, 1), groups=k)


def ssim_map(a: torch.Tensor, b: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """[H, W] structural similarity of [H, W, C] images in [0, 1] at each pixel, averaged over channels
    (Wang et al. 2004, gaussian 11×11, σ 1.5, zero-padded like the 3DGS loss). Differentiable."""
    c = a.shape[-1]
    x, y = a.permute(2, 0, 1)[None], b.permute(2, 0, 1)[None]  # [1, C, H, W]
    # The five local means in one pass, the 11×11 window as a row and a column of 11 taps (the same sums
    # with zero padding, a fifth of the multiplications): SSIM runs in every training and pose-fitting step.
    stack = separable_blur(torch.cat([x, y, x * x, y * y, x * y], 1), _gaussian(window, sigma, a.device))
    mx, my, exx, eyy, exy = stack.split(c, 1)
    sxx, syy, sxy = exx - mx**2, eyy - my**2, exy - mx * my
    c1, c2 = 0.01**2, 0.03**2
    s = ((2 * mx * my + c1) * (2 * sxy + c2)) / ((mx**2 + my**2 + c1) * (sxx + syy + c2))
    return s[0].mean(0)


def ssim(a: torch.Tensor, b: torch.Tensor, window: int = 11, sigma: float = 1.5) -> torch.Tensor:
    """Mean structural similarity of [H, W, C] images in [0, 1] (:func:`ssim_map` averaged); returns a
    scalar tensor."""
    return ssim_map(a, b, window, sigma).mean()


def person_box(mask: torch.Tensor, pad: float = 0.05) -> tuple[int, int, int, int] | None:
    """(y0, y1, x0, x1) of the bounding box of ``mask`` [H, W, 1] > 0.5, grown by ``pad`` × its larger side
    on every side and clipped to the image; None when the mask is empty."""
    ys, xs = torch.nonzero(mask[..., 0] > 0.5, as_tuple=True)
    if len(ys) == 0:
        return None
    h, w = mask.shape[:2]
    y0, y1, x0, x1 = int(ys.min()), int(ys.max()) + 1, int(xs.min()), int(xs.max()) + 1
    m = round(pad * max(y1 - y0, x1 - x0))
    return max(0, y0 - m), min(h, y1 + m), max(0, x0 - m), min(w, x1 + m)


def box_metrics(render: torch.Tensor, target: torch.Tensor, mask: torch.Tensor) -> dict[str, float]:
    """PSNR and SSIM of [H, W, 3] images inside the person's bounding box (``person_box`` of ``mask``):
    full-image scores count the easy uniform background, which is most of a portrait frame. The whole
    image when the mask is empty."""
    y0, y1, x0, x1 = person_box(mask) or (0, render.shape[0], 0, render.shape[1])
    a, b = render[y0:y1, x0:x1], target[y0:y1, x0:x1]
    return {"psnr_bbox": psnr(a, b), "ssim_bbox": float(ssim(a, b))}


def mask_iou(alpha: torch.Tensor, mask: torch.Tensor, threshold: float = 0.5) -> float:
    """Intersection over union of rendered ``alpha`` and the person ``mask`` (both [H, W, 1] in [0, 1]),
    each thresholded at ``threshold``; 1 when both are empty."""
    a, m = alpha > threshold, mask > threshold
    union = int((a | m).sum())
    return 1.0 if union == 0 else int((a & m).sum()) / union
