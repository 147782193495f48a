"""Loss terms of the two-stage fit: picture (L1, SSIM, mask, optional LPIPS) and geometry (Laplacian,
relative edge, 2DGS normal consistency)."""

from __future__ import annotations

import os
from pathlib import Path

import torch
import torch.nn.functional as F

from gma.body.geometry import mesh_edges, uniform_laplacian
from gma.train.metrics import ssim

__all__ = ["GeometryTerms", "depth_normals", "load_lpips", "normal_consistency"]


class GeometryTerms:
    """Mesh-layer regularisers for one topology (the Laplacian and edges are built once).

    laplacian(offsets [V, 3]): mean ||L·offsets||², the Laplacian of the *displacement* rather than of
    the morphed vertices — the body's own curvature is not a defect, only a rough morph is.
    edge(rest [V, 3], offsets [V, 3]): mean squared relative change of edge lengths between the body
    mesh with and without the offsets (the paper's relative edge loss).
    """

    def __init__(self, faces: torch.Tensor, num_vertices: int):
        self.L = uniform_laplacian(faces, num_vertices).coalesce()
        self.edges = mesh_edges(faces)

    def laplacian(self, offsets: torch.Tensor) -> torch.Tensor:
        return torch.sparse.mm(self.L, offsets).pow(2).sum(-1).mean()

    def edge(self, rest: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
        a, b = self.edges[:, 0], self.edges[:, 1]
        l0 = (rest[a] - rest[b]).norm(dim=-1).clamp_min(1e-6)
        l1 = (rest[a] + offsets[a] - rest[b] - offsets[b]).norm(dim=-1)
        return ((l1 - l0) / l0).pow(2).mean()


def depth_normals(depth: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """Camera-space unit normals [H, W, 3] of the surface given by a depth map [H, W, 1] (z, metres),
    facing the camera (central differences; zero on the border)."""
    h, w = depth.shape[:2]
    ys, xs = torch.meshgrid(torch.arange(h, dtype=depth.dtype), torch.arange(w, dtype=depth.dtype), indexing="ij")
    x = (xs + 0.5 - K[0, 2]) / K[0, 0]
    y = (ys + 0.5 - K[1, 2]) / K[1, 1]
    z = depth[..., 0]
    p = torch.stack([x * z, y * z, z], -1)
    dx = p[1:-1, 2:] - p[1:-1, :-2]
    dy = p[2:, 1:-1] - p[:-2, 1:-1]
    n = -F.normalize(torch.linalg.cross(dx, dy, dim=-1), dim=-1)  # x right, y down: dx × dy points away
    return F.pad(n.permute(2, 0, 1), (1, 1, 1, 1)).permute(1, 2, 0)


def normal_consistency(normal: torch.Tensor, depth: torch.Tensor, alpha: torch.Tensor, K: torch.Tensor) -> torch.Tensor:
    """2DGS's normal loss: 1 − ⟨rendered normal, normal of the rendered depth⟩, averaged over covered
    pixels. normal [H, W, 3] (Σ w n), depth [H, W, 1] (Σ w z), alpha [H, W, 1]."""
    a = alpha.clamp_min(1e-4)
    d = depth / a  # expected depth of the surface, not attenuated by partial coverage
    nd = depth_normals(d, K)
    cover = (alpha[..., 0] > 0.5).float()
    dot = (normal * nd).sum(-1)
    return ((1 - dot) * cover).sum() / cover.sum().clamp_min(1.0)


class _Lpips(torch.nn.Module):
    def __init__(self, net):
        super().__init__()
        self.net = net

    def forward(self, a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
        x, y = a.permute(2, 0, 1)[None] * 2 - 1, b.permute(2, 0, 1)[None] * 2 - 1
        return self.net(x, y).mean()


def load_lpips(verbose: bool = True):
    """An LPIPS loss module ``(a [H,W,3], b [H,W,3]) -> scalar`` when everything it needs is already on
    this machine, else None (with a one-line notice). It never downloads: it needs the ``lpips`` package
    (which ships the linear-layer weights) and the AlexNet backbone in torch's hub cache, or
    ``$GMA_LPIPS_WEIGHTS`` naming that backbone file."""
    def notice(why: str):
        if verbose:
            print(f"[gma] LPIPS skipped: {why}")
        return None

    try:
        import lpips
    except ImportError:
        return notice("the 'lpips' package is not installed")
    backbone = os.environ.get("GMA_LPIPS_WEIGHTS") or str(
        Path(torch.hub.get_dir()) / "checkpoints" / "alexnet-owt-7be5be79.pth")
    if not Path(backbone).is_file():
        return notice(f"AlexNet weights not found at {backbone} (set GMA_LPIPS_WEIGHTS)")
    import torchvision

    net = lpips.LPIPS(net="alex", pretrained=True, pnet_rand=True, verbose=False)
    alex = torchvision.models.alexnet()
    alex.load_state_dict(torch.load(backbone, weights_only=True))
    feats = alex.features
    for slice_, idx in zip((net.net.slice1, net.net.slice2, net.net.slice3, net.net.slice4, net.net.slice5),
                           ((0, 2), (2, 5), (5, 8), (8, 10), (10, 12)), strict=True):
        for i in range(*idx):
            slice_._modules[str(i)] = feats[i]
    net.eval().requires_grad_(False)
    return _Lpips(net)


def picture_loss(render: torch.Tensor, target: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(L1, 1 − SSIM) of [H, W, 3] images."""
    return (render - target).abs().mean(), 1 - ssim(render, target)
