"""Public render functions on torch tensors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.gpu import GpuContext, get_context
from gma.render.camera import Camera
from gma.render.rasterizer import SurfelRasterizer, read_outputs
from gma.render.surfels import SurfelBuffers
from gma.render.validate import check_background, check_camera, check_surfels


@dataclass
class RenderOutput:
    """``color`` [H, W, C], ``alpha`` [H, W, 1], ``normal`` [H, W, 3] (camera space), ``depth`` [H, W, 1]."""

    color: torch.Tensor
    alpha: torch.Tensor
    normal: torch.Tensor
    depth: torch.Tensor


_rasterizers: dict[int, SurfelRasterizer] = {}


def rasterizer_for(ctx: GpuContext) -> SurfelRasterizer:
    """One rasterizer per context, so its capacity hint and pipelines are reused between calls."""
    r = _rasterizers.get(id(ctx))
    if r is None or r.ctx is not ctx:
        r = _rasterizers[id(ctx)] = SurfelRasterizer(ctx)
    return r


def _host(t: torch.Tensor) -> np.ndarray:
    return t.detach().to("cpu", torch.float32).contiguous().numpy()


def rasterize(means, quats, scales, opacities, colors, viewmat, K, width: int, height: int,
              background=None, ctx: GpuContext | None = None) -> RenderOutput:
    """Render 2D Gaussian surfels (DESIGN.md "Renderer contract") with the WGSL renderer.

    Args:
        means: [N, 3] world positions. quats: [N, 4] rotations (w, x, y, z), normalised internally.
        scales: [N, 2] activated in-plane scales (>= 0). opacities: [N] activated, in [0, 1].
        colors: [N, C] per-surfel features (C >= 1; 3 for RGB). viewmat: [4, 4] world->camera (OpenCV).
        K: [3, 3] intrinsics in pixels. width, height: image size. background: [C] or None (zeros).
        ctx: GPU context (default: the shared one).
    Returns:
        :class:`RenderOutput` with float32 tensors on the device of ``means``.
    """
    means, quats, scales, opacities, colors = check_surfels(means, quats, scales, opacities, colors)
    viewmat, K, width, height = check_camera(viewmat, K, width, height)
    background = check_background(background, colors.shape[1])
    ctx = ctx or get_context()
    surfels = SurfelBuffers.from_arrays(ctx, _host(means), _host(quats), _host(scales), _host(opacities),
                                        _host(colors))
    camera = Camera(_host(viewmat), _host(K), width, height)
    bg = None if background is None else _host(background)
    state = rasterizer_for(ctx).forward(surfels, camera, bg)
    out = read_outputs(ctx, state)
    dev = means.device
    return RenderOutput(*(torch.from_numpy(a).to(dev) for a in (out.color, out.alpha, out.normal, out.depth)))
