"""Public render functions on torch tensors."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.core.camera import Camera
from gma.gpu import GpuContext, get_context
from gma.gpu.openmp_workers import openmp_workers_asleep
from gma.render.rasterizer import SurfelRasterizer, read_outputs
from gma.render.surfels import SurfelBuffers
from gma.render.validate import check_background, check_camera, check_surfel_values, check_surfels, host_array


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


class _RasterizeFunction(torch.autograd.Function):
    """Bridges torch autograd and the WGSL passes. Forward keeps exactly what backward needs (the
    typed :class:`ForwardState` and the uploaded surfels) on the GPU; backward uploads the upstream
    image gradients, runs the two backward passes and reads back the surfel gradients. Host-side work is
    numpy (see :func:`gma.render.validate.host_array` for why not torch)."""

    @staticmethod
    def forward(fctx, means, quats, scales, opacities, colors, viewmat, K, background, width, height, gpu, host,
                replay):
        fctx.set_materialize_grads(False)  # unused outputs arrive as None and cost nothing
        # On a CPU adapter torch's idle OpenMP workers would spin on the cores the render runs on.
        with openmp_workers_asleep(active=gpu.is_software):
            return _RasterizeFunction._forward(fctx, means, viewmat, K, background, width, height, gpu, host, replay)

    @staticmethod
    def _forward(fctx, means, viewmat, K, background, width, height, gpu, host, replay):
        # host: float32 copies of the five surfel tensors; the buffers are recycled once the autograd graph
        # lets go of this call (gma/gpu/recycle.py), as are the forward state's.
        surfels = SurfelBuffers.from_arrays(gpu, *host, recycled=True)
        camera = Camera(host_array(viewmat), host_array(K), width, height)
        bg = None if background is None else host_array(background)
        rast = rasterizer_for(gpu)
        # The surfels' values are checked while the GPU projects them, so the checks cost no wall time;
        # nothing after projection runs on values that fail.
        state = rast.forward(surfels, camera, bg, replay=replay, read_images=True,
                             while_projecting=lambda: check_surfel_values(host))
        out = read_outputs(gpu, state)
        fctx.state, fctx.surfels, fctx.rast = state, surfels, rast
        fctx.device = means.device
        fctx.has_background = background is not None
        fctx.alpha = out.alpha  # [H, W, 1] numpy, for the background gradient
        return tuple(torch.from_numpy(a).to(means.device) for a in (out.color, out.alpha, out.normal, out.depth))

    @staticmethod
    def backward(fctx, v_color, v_alpha, v_normal, v_depth):
        needs = fctx.needs_input_grad
        if not any(needs[:5]) and not needs[7]:
            return (None,) * 13
        with openmp_workers_asleep(active=fctx.rast.ctx.is_software):
            return _RasterizeFunction._backward(fctx, needs, v_color, v_alpha, v_normal, v_depth)

    @staticmethod
    def _backward(fctx, needs, v_color, v_alpha, v_normal, v_depth):
        upstream = [None if g is None else host_array(g) for g in (v_color, v_alpha, v_normal, v_depth)]
        dev = fctx.device
        result = [None] * 5
        if any(needs[:5]):
            grads = fctx.rast.backward(fctx.state, fctx.surfels, *upstream)
            result = [torch.from_numpy(g).to(dev) if need else None for g, need in
                      zip((grads.means, grads.quats, grads.scales, grads.opacities, grads.colors), needs)]
        v_background = None
        if needs[7] and fctx.has_background and v_color is not None:
            # colour = sum w c + (1 - alpha) background: d/d background = sum over pixels of v_color (1 - alpha).
            v_bg = (upstream[0] * (1 - fctx.alpha)).sum(axis=(0, 1), dtype=np.float64).astype(np.float32)
            v_background = torch.from_numpy(v_bg).to(dev)
        return (*result, None, None, v_background, None, None, None, None, None)


def rasterize(means, quats, scales, opacities, colors, viewmat, K, width: int, height: int,
              background=None, ctx: GpuContext | None = None) -> RenderOutput:
    """Render 2D Gaussian surfels (docs/design.md "Renderer contract") with the WGSL renderer; differentiable.

    Args:
        means: [N, 3] world positions. quats: [N, 4] rotations (w, x, y, z), normalised internally.
        scales: [N, 2] activated in-plane scales (>= 0). opacities: [N] activated, in [0, 1].
        colors: [N, C] per-surfel features (C >= 1; 3 for RGB). viewmat: [4, 4] world->camera (OpenCV).
        K: [3, 3] intrinsics in pixels. width, height: image size. background: [C] or None (zeros).
        ctx: GPU context (default: the shared one).
    Returns:
        :class:`RenderOutput` with float32 tensors on the device of ``means``. When any of means, quats,
        scales, opacities, colors or background requires grad, the outputs carry a ``grad_fn`` whose
        backward runs the WGSL backward passes (camera gradients are not computed).
    """
    # Types and shapes here; values while the GPU projects (_RasterizeFunction.forward).
    (means, quats, scales, opacities, colors), host = check_surfels(means, quats, scales, opacities, colors,
                                                                     values=False)
    viewmat, K, width, height = check_camera(viewmat, K, width, height)
    background = check_background(background, colors.shape[1])
    gpu = ctx or get_context()
    # A render that no surfel gradient can come back to (none requires grad, or grad mode is off, as in
    # an evaluation under torch.no_grad) keeps nothing for the backward pass (SurfelRasterizer.forward).
    replay = torch.is_grad_enabled() and any(t.requires_grad for t in (means, quats, scales, opacities, colors))
    outs = _RasterizeFunction.apply(means, quats, scales, opacities, colors, viewmat, K, background, width, height,
                                    gpu, host, replay)
    return RenderOutput(*outs)
