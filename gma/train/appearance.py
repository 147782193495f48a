"""What a frame's picture owes to the camera rather than to the person, kept out of the avatar's texture.

- **Per-frame colour** (:class:`FrameColour`). A phone changes exposure and white balance while it films;
  an avatar fitted to such frames averages its texture over them. Each training frame therefore gets a
  small colour transform of its own, a gain and an offset per channel applied to the rendered person
  (not to the background behind it), learnt with the avatar and pulled toward identity. The avatar keeps
  the colours common to all frames; the transforms are discarded with the fit, and held-out frames get
  their own at evaluation, fitted with test-time pose fitting (``gma eval --refine-poses``).
- **Colour-loss weights** (:func:`colour_weights`). A pixel outside the person's mask says nothing about
  the person's colour: a surfel that lands there (a pose a few pixels off, a thin limb) would learn the
  background's grey and show as see-through. The pixels just inside the mask's edge mix the person with
  the real background (a green screen's green, a white wall). The colour loss therefore weighs a pixel 0
  outside the mask, rising to 1 over the ``edge`` pixels inside its boundary; the mask loss alone keeps
  the outline.
- **Unmixing the background** (:func:`unmix_background`). Where the mask is soft, a pixel is
  ``m F + (1 - m) B``: the person ``F`` over the real background ``B``. Composited over the fit's grey as
  it is, the target keeps ``m (1 - m) B`` of the real background (green at a green screen's edges). The
  background colour around each pixel is estimated from the frame's own background pixels and taken out.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from scipy import ndimage
from torch import nn

from gma.train.config import FrameColourConfig
from gma.train.metrics import ssim, ssim_map
from gma.train.pose_refine import VIDEO_MARKER

__all__ = ["FrameColour", "colour_wanted", "colour_weights", "unmix_background", "weighted_picture_loss"]

# The local background colour is a mean over background pixels within a Gaussian of this size (times
# the image's longer side): wide enough to reach past a limb into the background beside it, narrow
# enough to follow a wall's shading or a green screen's uneven lighting.
BACKGROUND_SIGMA = 0.03
# Pixels whose mask is below this are background (a soft mask's faint halo is not).
BACKGROUND_BELOW = 0.02


def colour_wanted(cfg: FrameColourConfig, seq) -> bool:
    """Whether sequence ``seq``'s frames get colour transforms under ``cfg.refine`` (auto: frames filmed
    by a camera that sets its own exposure, i.e. sequences from ``gma import video``)."""
    if cfg.refine == "auto":
        return (Path(seq.root) / VIDEO_MARKER).is_file()
    return cfg.refine == "on"


def colour_weights(masks: torch.Tensor, edge: float) -> torch.Tensor:
    """Colour-loss weight [T, H, W, 1] in [0, 1] of each pixel of frames with person ``masks``
    [T, H, W, 1]: 0 outside the mask (< 0.5), rising linearly with the distance to the mask's boundary to
    1 at ``edge`` pixels inside. ``edge`` 0: weight 1 everywhere (the colour loss over the whole image)."""
    if edge <= 0:
        return torch.ones_like(masks)
    inside = masks[..., 0].numpy() > 0.5
    # Distance of each person pixel to the nearest background pixel: 1 on the boundary's inner row.
    dist = np.stack([ndimage.distance_transform_edt(m) for m in inside]).astype(np.float32)
    return torch.from_numpy(np.clip(dist / edge, 0.0, 1.0))[..., None]


def unmix_background(images: torch.Tensor, masks: torch.Tensor) -> torch.Tensor:
    """``images`` [T, H, W, 3] with the real background taken out of the person's soft edges: each pixel
    ``I = m F + (1 - m) B`` becomes ``F = (I - (1 - m) B) / m`` (clamped to [0, 1]), with ``B`` the mean
    colour of the frame's background pixels (mask < ``BACKGROUND_BELOW``) around it, and ``masks``
    [T, H, W, 1] the ``m``. Pixels with ``m`` = 1 are unchanged; pixels with ``m`` = 0 are left as they are
    (the target shows the fit's own background there)."""
    from gma.train.metrics import separable_blur

    t, h, w, _ = images.shape
    sigma = max(1.0, BACKGROUND_SIGMA * max(h, w))
    radius = int(3 * sigma)
    x = torch.arange(-radius, radius + 1, dtype=torch.float32)
    kernel = torch.exp(-0.5 * (x / sigma) ** 2)
    out = images.clone()
    for i in range(t):
        m = masks[i]                                                         # [H, W, 1]
        bg = (m < BACKGROUND_BELOW).float()
        if not bool(bg.any()):
            continue  # the person fills the frame: no background to estimate
        stack = torch.cat([images[i] * bg, bg], -1).permute(2, 0, 1)[None]  # [1, 4, H, W]
        sums = separable_blur(stack, kernel)[0].permute(1, 2, 0)
        fallback = (images[i] * bg).sum((0, 1)) / bg.sum()                   # far from any background
        local = torch.where(sums[..., 3:] > 1e-3, sums[..., :3] / sums[..., 3:].clamp_min(1e-3), fallback)
        soft = (m > 0) & (m < 1)
        person = ((images[i] - (1 - m) * local) / m.clamp_min(1e-3)).clamp(0, 1)
        out[i] = torch.where(soft, person, images[i])
    return out


def weighted_picture_loss(render: torch.Tensor, target: torch.Tensor, weight: torch.Tensor | None
                          ) -> tuple[torch.Tensor, torch.Tensor]:
    """(L1, 1 − SSIM) of [H, W, 3] images, each pixel's share scaled by ``weight`` [H, W, 1] (None: 1).
    Both stay means over the whole image, so a weight of 1 everywhere gives the unweighted loss and the
    balance with the other terms does not depend on how much of the image the person covers."""
    if weight is None:
        return (render - target).abs().mean(), 1 - ssim(render, target)
    l1 = ((render - target).abs() * weight).mean()
    dssim = ((1 - ssim_map(render, target)) * weight[..., 0]).mean()
    return l1, dssim


class FrameColour(nn.Module):
    """Per-channel gain and offset of each of T frames, ``c' = (1 + g) c + b`` on the rendered person
    (colour premultiplied by its alpha, so the offset fades with coverage and the background is left
    alone). Each frame's parameters are their own tensors: Adam moves a frame only on the steps that draw
    it, as for pose corrections."""

    def __init__(self, frames: int):
        super().__init__()
        self.gain = nn.ParameterList([nn.Parameter(torch.zeros(3)) for _ in range(frames)])
        self.offset = nn.ParameterList([nn.Parameter(torch.zeros(3)) for _ in range(frames)])

    def __len__(self) -> int:
        return len(self.gain)

    def params(self, t: int) -> list[nn.Parameter]:
        return [self.gain[t], self.offset[t]]

    def apply(self, t: int, color: torch.Tensor, alpha: torch.Tensor, background: float) -> torch.Tensor:
        """Frame ``t``'s transform of a render: ``color`` [H, W, 3] composited over a uniform ``background``,
        ``alpha`` [H, W, 1] its coverage. Returns the transformed render, composited the same way."""
        behind = background * (1 - alpha)
        person = color - behind                                  # premultiplied colour of the person
        return (1 + self.gain[t]) * person + alpha * self.offset[t] + behind

    def regulariser(self, t: int) -> torch.Tensor:
        """Squared distance of frame ``t``'s transform from identity (gain and offset, summed)."""
        return self.gain[t].pow(2).sum() + self.offset[t].pow(2).sum()

    def summary(self) -> dict:
        """Mean and largest |gain| and |offset| over frames and channels."""
        with torch.no_grad():
            g = torch.stack(list(self.gain)).abs()
            b = torch.stack(list(self.offset)).abs()
        return {"mean_gain": float(g.mean()), "max_gain": float(g.max()), "mean_offset": float(b.mean()),
                "max_offset": float(b.max())}
