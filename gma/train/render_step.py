"""One differentiable render of a decoded avatar for one training frame (torch posing + WGSL raster)."""

from __future__ import annotations

import torch

from gma.avatar.model import DecodedAvatar
from gma.avatar.posing import PosedSurfels, pose_surfels
from gma.render import RenderOutput, rasterize
from gma.train.data import FrameSet

__all__ = ["render_frame"]


def render_frame(decoded: DecodedAvatar, body, frames: FrameSet, t: int, background: float, ctx=None,
                 cull: bool = True, on_means=None, bones: torch.Tensor | None = None,
                 ) -> tuple[RenderOutput, PosedSurfels]:
    """Pose ``decoded`` for frame ``t`` of ``frames`` and render it at the frames' resolution; with
    ``cull``, only the surfels on faces not turned away from the camera are placed and drawn (the
    returned ``PosedSurfels`` holds those, ``rows`` saying which).

    ``bones`` [J, 4, 4] (optional) replaces the frame's precomputed bone transforms: refined poses.
    ``on_means`` (optional) is registered as a gradient hook on the surfel means handed to the renderer:
    it fires when the renderer's backward has finished (the trainer times that split with it)."""
    bones = frames.bones[t] if bones is None else bones
    posed = pose_surfels(decoded, body.faces, body.skin_indices, body.skin_weights, frames.rest[t], bones,
                         visible_from=frames.w2c[t] if cull else None)
    means, quats, scales, colors, opac = (posed[k] for k in ("means", "quats", "scales", "colors", "opacities"))
    if on_means is not None and means.requires_grad:
        means.register_hook(on_means)
    h, w = frames.images.shape[1:3]
    out = rasterize(means, quats, scales, opac, colors, frames.w2c[t], frames.K[t], w, h,
                    background=torch.full((3,), float(background)), ctx=ctx)
    return out, posed
