"""Pure-torch reference of the renderer contract (docs/design.md, "Renderer contract"): per pixel, every
surfel, no tiles and no screen-bound culling. Slow and memory-hungry by design; it is the oracle the
WGSL passes are tested against, and it is differentiable (float64 works for gradcheck)."""

from __future__ import annotations

import torch
from torch import Tensor

from gma.render.layouts import ALPHA_THRESHOLD, MAX_ALPHA, NEAR_PLANE, TRANSMITTANCE_EPS


def quat_to_rotmat(quats: Tensor) -> Tensor:
    """``quats`` [N, 4] (w, x, y, z), normalised here -> rotation matrices [N, 3, 3]."""
    q = quats / quats.norm(dim=-1, keepdim=True)
    w, x, y, z = q.unbind(-1)
    return torch.stack(
        [
            1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y),
            2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x),
            2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y),
        ],
        dim=-1,
    ).reshape(*q.shape[:-1], 3, 3)


def project_reference(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, viewmat: Tensor,
                      K: Tensor):
    """Per-surfel quantities. Returns (T [N, 3, 3], mu2d [N, 2], normal [N, 3], depth [N], valid [N])."""
    R, t = viewmat[:3, :3], viewmat[:3, 3]
    mu_c = means @ R.T + t                                            # [N, 3]
    rot = R @ quat_to_rotmat(quats)                                   # [N, 3, 3]
    tu = rot[:, :, 0] * scales[:, :1]
    tv = rot[:, :, 1] * scales[:, 1:2]
    normal = rot[:, :, 2]
    facing = torch.where((normal * mu_c).sum(-1, keepdim=True) > 0, -1.0, 1.0).to(normal)
    normal = normal * facing
    T = K @ torch.stack([tu, tv, mu_c], dim=-1)                       # [N, 3, 3] = K [tu, tv, mu_c]
    denom = T[:, 2, 0] ** 2 + T[:, 2, 1] ** 2 - T[:, 2, 2] ** 2
    valid = (mu_c[:, 2] > NEAR_PLANE) & (opacities >= ALPHA_THRESHOLD) & (denom != 0)
    safe = torch.where(denom != 0, denom, torch.ones_like(denom))
    f = torch.stack([torch.ones_like(denom), torch.ones_like(denom), -torch.ones_like(denom)], -1) / safe[:, None]
    mu2d = torch.stack([(f * T[:, 0] * T[:, 2]).sum(-1), (f * T[:, 1] * T[:, 2]).sum(-1)], -1)
    return T, mu2d, normal, mu_c[:, 2], valid


def surfel_alpha_reference(T: Tensor, mu2d: Tensor, opacities: Tensor, pixels: Tensor) -> Tensor:
    """Alpha of every surfel at every pixel centre. ``pixels`` [P, 2] -> [P, N]."""
    x, y = pixels[:, 0, None, None], pixels[:, 1, None, None]        # [P, 1, 1]
    h_u = x * T[None, :, 2] - T[None, :, 0]                           # [P, N, 3]
    h_v = y * T[None, :, 2] - T[None, :, 1]
    p = torch.linalg.cross(h_u, h_v)
    d = pixels[:, None, :] - mu2d[None]                               # [P, N, 2]
    sigma_2d = (d * d).sum(-1)
    pz_ok = p[..., 2] != 0
    pz = torch.where(pz_ok, p[..., 2], torch.ones_like(p[..., 2]))
    sigma_3d = 0.5 * ((p[..., 0] / pz) ** 2 + (p[..., 1] / pz) ** 2)
    sigma = torch.where(pz_ok, torch.minimum(sigma_3d, sigma_2d), sigma_2d)
    return torch.clamp(opacities[None] * torch.exp(-sigma), max=MAX_ALPHA)


def rasterize_reference(means: Tensor, quats: Tensor, scales: Tensor, opacities: Tensor, colors: Tensor,
                        viewmat: Tensor, K: Tensor, width: int, height: int, background: Tensor | None = None,
                        pixel_chunk: int = 4096) -> dict[str, Tensor]:
    """Render with the contract's exact math. Returns dict of color [H, W, C], alpha [H, W, 1],
    normal [H, W, 3], depth [H, W, 1]."""
    dev, dt = means.device, means.dtype
    C = colors.shape[1]
    T, mu2d, normal, depth, valid = project_reference(means, quats, scales, opacities, viewmat, K)
    idx = torch.nonzero(valid).squeeze(1)
    order = idx[torch.sort(depth[idx], stable=True).indices]          # front to back, ties by index
    T, mu2d, normal, depth = T[order], mu2d[order], normal[order], depth[order]
    opac, cols = opacities[order], colors[order]
    ys, xs = torch.meshgrid(torch.arange(height, device=dev), torch.arange(width, device=dev), indexing="ij")
    pixels = torch.stack([xs.reshape(-1), ys.reshape(-1)], -1).to(dt) + 0.5
    outs = {"color": [], "alpha": [], "normal": [], "depth": []}
    for start in range(0, pixels.shape[0], pixel_chunk):
        px = pixels[start:start + pixel_chunk]
        if order.numel() == 0:
            w = torch.zeros(px.shape[0], 0, device=dev, dtype=dt)
        else:
            alpha = surfel_alpha_reference(T, mu2d, opac, px)          # [P, M]
            alpha = torch.where(alpha < ALPHA_THRESHOLD, torch.zeros_like(alpha), alpha)
            trans_after = torch.cumprod(1 - alpha, dim=1)              # T after each surfel
            # Compositing stops before the first surfel that would bring T to <= 1e-4; T only falls, so
            # every later surfel is excluded as well.
            keep = (trans_after > TRANSMITTANCE_EPS).to(dt)
            trans_before = torch.cat([torch.ones_like(trans_after[:, :1]), trans_after[:, :-1]], 1)
            w = alpha * trans_before * keep
        outs["color"].append(w @ cols)
        outs["alpha"].append(w.sum(1, keepdim=True))
        outs["normal"].append(w @ normal)
        outs["depth"].append(w @ depth[:, None])
    res = {k: torch.cat(v, 0) for k, v in outs.items()}
    if background is not None:
        res["color"] = res["color"] + (1 - res["alpha"]) * background[None]
    return {
        "color": res["color"].reshape(height, width, C),
        "alpha": res["alpha"].reshape(height, width, 1),
        "normal": res["normal"].reshape(height, width, 3),
        "depth": res["depth"].reshape(height, width, 1),
    }
