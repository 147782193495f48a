"""Frames of a sequence as tensors at the fitting resolution, with per-frame body rest vertices and bone
transforms precomputed (the body parameters are fixed while fitting, so only the avatar learns)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
import torch.nn.functional as F

from gma.avatar.posing import frame_params
from gma.train.validate import check_frames

__all__ = ["FrameSet", "load_frames"]


@dataclass
class FrameSet:
    """T frames. images [T, h, w, 3] and masks [T, h, w, 1] in [0, 1]; K [T, 3, 3] (scaled to h × w);
    w2c [T, 4, 4]; rest [T, V, 3] body rest vertices (shape + expression); bones [T, J, 4, 4];
    indices [T] frame numbers in the sequence; shape [S] the body identity; poses [T, ...] the body's
    per-frame "pose" parameters the bones were made from (Anny: [T, J, 4, 4] local-ref transforms)."""

    images: torch.Tensor
    masks: torch.Tensor
    K: torch.Tensor
    w2c: torch.Tensor
    rest: torch.Tensor
    bones: torch.Tensor
    indices: list[int]
    shape: torch.Tensor
    poses: torch.Tensor

    def __len__(self) -> int:
        return len(self.indices)

    def target(self, t: int, background: float) -> torch.Tensor:
        """[h, w, 3] image composited over a uniform ``background`` (what a render is compared with)."""
        m = self.masks[t]
        return self.images[t] * m + background * (1 - m)

    def subset(self, keep: list[int]) -> FrameSet:
        """The frames at positions ``keep`` (indices into this set, not frame numbers), in that order."""
        pick = torch.as_tensor(keep, dtype=torch.long)
        return FrameSet(self.images[pick], self.masks[pick], self.K[pick], self.w2c[pick], self.rest[pick],
                        self.bones[pick], [self.indices[k] for k in keep], self.shape, self.poses[pick])

    def resized(self, resolution: int) -> FrameSet:
        """The same frames with the longest side at most ``resolution`` (area-downsampled, intrinsics
        scaled; never upscaled): a fit's stages may render at different sizes."""
        h, w = self.images.shape[1:3]
        s = min(1.0, resolution / max(h, w))
        size = (max(8, round(h * s)), max(8, round(w * s)))
        if size == (h, w):
            return self
        images = F.interpolate(self.images.permute(0, 3, 1, 2), size=size, mode="area").permute(0, 2, 3, 1)
        masks = F.interpolate(self.masks.permute(0, 3, 1, 2), size=size, mode="area").permute(0, 2, 3, 1)
        K = self.K.clone()
        K[:, 0] *= size[1] / w
        K[:, 1] *= size[0] / h
        return FrameSet(images, masks, K, self.w2c, self.rest, self.bones, self.indices, self.shape, self.poses)


def _resize(x: np.ndarray, size: tuple[int, int]) -> torch.Tensor:
    t = torch.from_numpy(np.ascontiguousarray(x)).float().permute(2, 0, 1)[None]
    if tuple(t.shape[-2:]) != size:
        t = F.interpolate(t, size=size, mode="area")
    return t[0].permute(1, 2, 0)


def load_frames(seq, body, split: str, resolution: int, max_frames: int = 0,
                identity: torch.Tensor | None = None) -> FrameSet:
    """Frames of ``split`` of sequence ``seq`` (``gma.data.Sequence``), resized so the longest side is
    ``resolution`` (never upscaled); ``max_frames`` > 0 keeps that many, evenly spaced. ``identity`` [S]
    replaces the sequence's body identity (phenotype / betas) in every frame: an avatar is posed with the
    body it was fitted on."""
    idx = seq.split(split)
    if not idx:
        raise ValueError(f"{seq.root}: split {split!r} is empty or missing (splits: {sorted(seq.splits)})")
    if max_frames and len(idx) > max_frames:
        idx = [idx[int(i)] for i in np.linspace(0, len(idx) - 1, max_frames).round()]
    s = min(1.0, resolution / max(seq.width, seq.height))
    h, w = max(8, round(seq.height * s)), max(8, round(seq.width * s))
    sx, sy = w / seq.width, h / seq.height
    images, masks, Ks, w2cs, rests, bones, poses = [], [], [], [], [], [], []
    with torch.no_grad():
        for i in idx:
            images.append(_resize(seq.image(i).astype(np.float32) / 255.0, (h, w)))
            masks.append(_resize(seq.mask(i)[..., None], (h, w)))
            K, w2c = seq.cameras.frame(i)
            K = torch.as_tensor(K, dtype=torch.float32).clone()
            K[0] *= sx
            K[1] *= sy
            Ks.append(K)
            w2cs.append(torch.as_tensor(w2c, dtype=torch.float32))
            params = frame_params(seq.body.model, seq.body.frame(i))
            if identity is not None:
                params["shape"] = identity
            params = body.check_params(params)
            rests.append(body.rest_vertices(params).float())
            bones.append(body.bone_transforms(params).float())
            poses.append(params["pose"].float())
    frames = FrameSet(torch.stack(images), torch.stack(masks), torch.stack(Ks), torch.stack(w2cs),
                      torch.stack(rests), torch.stack(bones), list(idx), params["shape"].clone(), torch.stack(poses))
    check_frames(seq, frames, body)
    return frames
