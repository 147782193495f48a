"""Checks on the frames a fit or an evaluation reads, on their values rather than their shapes: a
sequence whose masks are empty, or whose body and cameras put the person behind the camera or outside
the image, would otherwise "fit" to a meaningless avatar with good-looking numbers."""

from __future__ import annotations

import torch

from gma.body.skinning import linear_blend_skinning
from gma.core.errors import InputError

__all__ = ["check_frames"]

# At the fitting resolution a person covers thousands of pixels; fewer than this is an empty mask.
MIN_MASK_PIXELS = 4.0
# The share of body vertices that must project in front of the camera and inside the image.
MIN_VISIBLE_SHARE = 0.1


def check_frames(seq, frames, body) -> None:
    """Raise :class:`InputError` naming the first frame of ``frames`` (a ``FrameSet`` of ``seq``) whose
    mask covers nothing, or whose posed body is behind the camera or outside the image."""
    coverage = frames.masks.sum(dim=(1, 2, 3))  # [T] pixels
    empty = (coverage < MIN_MASK_PIXELS).nonzero().flatten().tolist()
    if empty:
        i = frames.indices[empty[0]]
        where = seq.mask_paths[i] if seq.mask_paths is not None else seq.image_paths[i]
        raise InputError(f"{where}: the mask of frame {i} covers no pixel ({len(empty)} of {len(frames)} frames "
                         "are empty); the person must be masked in every frame that is fitted or evaluated")
    h, w = frames.images.shape[1:3]
    with torch.no_grad():
        posed = linear_blend_skinning(frames.rest, body.skin_indices, body.skin_weights, frames.bones)  # [T, V, 3]
        cam = posed @ frames.w2c[:, :3, :3].transpose(1, 2) + frames.w2c[:, None, :3, 3]
        z = cam[..., 2]
        pix = cam @ frames.K.transpose(1, 2)
        xy = pix[..., :2] / pix[..., 2:3].clamp_min(1e-6)
        inside = (z > 0.01) & (xy[..., 0] >= 0) & (xy[..., 0] < w) & (xy[..., 1] >= 0) & (xy[..., 1] < h)
        share = inside.float().mean(1)  # [T]
    bad = (share < MIN_VISIBLE_SHARE).nonzero().flatten().tolist()
    if bad:
        t = bad[0]
        where = "behind the camera" if bool((z[t] <= 0.01).float().mean() > 0.5) else "outside the image"
        raise InputError(f"{seq.root}: in frame {frames.indices[t]} the body of body.npz is {where} of "
                         f"cameras.json ({share[t]:.0%} of it visible; {len(bad)} of {len(frames)} frames): the two "
                         "files disagree (world->camera matrices inverted, or another body's poses?)")
