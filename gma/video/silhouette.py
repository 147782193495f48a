"""Soft silhouette of the posed body through the project's surfel renderer, for the mask term.

The posed mesh is drawn as one surfel per face on a fixed random subset of faces, each enlarged to
cover the faces left out, inside a small square crop around the detected person (e.g. 64 px) — enough
to pull the body's outline onto the mask at a cost a small CPU affords.

The renderer: ``gma.render.rasterize`` when it carries gradients (the WGSL renderer's autograd
function), otherwise the pure-torch ``rasterize_reference`` (exact, slow, fine at these sizes).
"""

from __future__ import annotations

import functools

import numpy as np
import roma
import torch
from PIL import Image

from gma.render import rasterize, rasterize_reference

__all__ = ["SilhouetteRenderer", "crop_box"]


@functools.lru_cache(maxsize=1)
def _wgsl_is_differentiable() -> bool:
    """Whether ``gma.render.rasterize`` returns an alpha that autograd reaches the means through."""
    try:
        means = torch.tensor([[0.0, 0.0, 2.0]], requires_grad=True)
        out = rasterize(means, torch.tensor([[1.0, 0, 0, 0]]), torch.full((1, 2), 0.2), torch.tensor([0.9]),
                        torch.ones(1, 3), torch.eye(4), torch.tensor([[8.0, 0, 4], [0, 8, 4], [0, 0, 1]]), 8, 8)
        if not out.alpha.requires_grad:
            return False
        out.alpha.sum().backward()
        return means.grad is not None and bool(torch.isfinite(means.grad).all())
    except Exception:  # no adapter, or a renderer without backward: use the torch reference
        return False


def crop_box(mask: np.ndarray, margin: float = 0.15) -> tuple[float, float, float] | None:
    """Square crop (x0, y0, side) in pixels around mask [H, W] > 0.5 with a relative margin, or None
    when the mask is empty."""
    ys, xs = np.nonzero(mask > 0.5)
    if len(xs) == 0:
        return None
    x0, x1, y0, y1 = xs.min(), xs.max() + 1, ys.min(), ys.max() + 1
    side = max(x1 - x0, y1 - y0) * (1 + 2 * margin)
    return (x0 + x1) / 2 - side / 2, (y0 + y1) / 2 - side / 2, float(side)


class SilhouetteRenderer:
    """Renders [size, size] soft masks of posed meshes inside per-frame crops."""

    def __init__(self, faces: torch.Tensor, num_faces: int = 3000, size: int = 96, seed: int = 0):
        g = torch.Generator().manual_seed(seed)
        n = min(num_faces, faces.shape[0])
        self.face_subset = torch.randperm(faces.shape[0], generator=g)[:n]
        self.faces = faces[self.face_subset]
        self.cover = faces.shape[0] / n  # each surfel stands for this many faces
        self.size = size
        self.use_wgsl = _wgsl_is_differentiable()

    def target(self, mask: np.ndarray, box: tuple[float, float, float]) -> torch.Tensor:
        """The detected mask [H, W] resampled into the crop: [size, size] in [0, 1]."""
        x0, y0, side = box
        img = Image.fromarray(np.asarray(mask, np.float32), mode="F")
        crop = img.transform((self.size, self.size), Image.Transform.EXTENT, (x0, y0, x0 + side, y0 + side),
                             Image.Resampling.BILINEAR)
        return torch.from_numpy(np.clip(np.asarray(crop), 0, 1).copy())

    def render(self, vertices: torch.Tensor, K: torch.Tensor, w2c: torch.Tensor,
               box: tuple[float, float, float]) -> torch.Tensor:
        """Soft mask [size, size] of the mesh with posed ``vertices`` [V, 3] (world), camera K [3, 3] and
        w2c [4, 4], cropped to ``box``."""
        x0, y0, side = box
        s = self.size / side
        Kc = K.clone()
        Kc[0, 0], Kc[1, 1] = K[0, 0] * s, K[1, 1] * s
        Kc[0, 2], Kc[1, 2] = (K[0, 2] - x0) * s, (K[1, 2] - y0) * s
        tri = vertices[self.faces]                                       # [N, 3, 3]
        centre = tri.mean(1)
        e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
        n = torch.linalg.cross(e1, e2)
        area = 0.5 * n.norm(dim=-1).clamp_min(1e-12)
        n = n / (2 * area[:, None])
        t = e1 / e1.norm(dim=-1, keepdim=True).clamp_min(1e-12)
        rot = torch.stack([t, torch.linalg.cross(n, t), n], -1)          # columns: tangent, bitangent, normal
        q = roma.rotmat_to_unitquat(rot.detach())                        # (x, y, z, w); orientation needs no grad
        quats = torch.cat([q[:, 3:], q[:, :3]], -1)
        scale = (0.5 * (area * self.cover).sqrt())[:, None].expand(-1, 2)
        opac = torch.full((len(centre),), 0.95)
        colors = torch.ones(len(centre), 1)
        if self.use_wgsl:
            return rasterize(centre, quats, scale, opac, colors, w2c, Kc, self.size, self.size).alpha[..., 0]
        out = rasterize_reference(centre, quats, scale, opac, colors, w2c, Kc, self.size, self.size,
                                  pixel_chunk=1024)
        return out["alpha"][..., 0]
