"""The comparison peer: gsplat 1.5.3's pure-PyTorch 2DGS path on the CPU (``peer_compare.py`` times it
beside GMA). Install it with ``BUILD_NO_CUDA=1 pip install gsplat==1.5.3``.

gsplat's own torch code does the projection (``_fully_fused_projection_2dgs``) and the compositing
(``accumulate_2dgs``). Two pieces it leaves to CUDA are replaced here by plain torch:

- which (surfel, pixel) pairs to composite (``rasterize_to_indices_in_range_2dgs`` is a CUDA kernel):
  ``_intersections`` enumerates the pixels inside each surfel's radius box, keeps alpha >= 1/255 and
  stops a pixel once its transmittance would fall to <= 1e-4, as the kernel does, sorted by pixel then
  depth, without gradients (like the kernel);
- nerfacc's ``render_weight_from_alpha`` and ``accumulate_along_rays``, which accept CUDA tensors only:
  a segmented exclusive product in log space and an ``index_add``, differentiable by autograd.
"""

from __future__ import annotations

import importlib.util
import sys
import types

ALPHA_MIN = 1.0 / 255.0
TRANSMITTANCE_MIN = 1e-4
INSTALL = "BUILD_NO_CUDA=1 pip install gsplat==1.5.3"


def missing_reason() -> str | None:
    """Why the peer cannot run here (one line), or None."""
    if importlib.util.find_spec("gsplat") is None:
        return f"gsplat not installed ({INSTALL})"
    return None


def load():
    """The peer's ``render`` function; call only when :func:`missing_reason` is None."""
    _install_nerfacc_stand_in()
    return render


def _exclusive_transmittance(alphas, ray_ids):
    """Transmittance in front of each entry along its ray; entries grouped by ray, front to back."""
    import torch

    n = alphas.shape[0]
    if n == 0:
        return alphas.new_ones(0)
    log_keep = torch.log1p(-alphas.double())  # float64: long rays would lose the product in float32
    before = torch.cumsum(log_keep, 0) - log_keep
    starts = torch.ones(n, dtype=torch.bool)
    starts[1:] = ray_ids[1:] != ray_ids[:-1]
    ray_start = torch.cummax(torch.where(starts, torch.arange(n), torch.zeros(n, dtype=torch.long)), 0)[0]
    return torch.exp(before - before[ray_start]).to(alphas.dtype)


def _render_weight_from_alpha(alphas, ray_indices=None, n_rays=None, **_):
    trans = _exclusive_transmittance(alphas, ray_indices)
    return alphas * trans, trans


def _accumulate_along_rays(weights, values=None, ray_indices=None, n_rays=None):
    import torch

    src = weights[:, None] if values is None else weights[:, None] * values
    out = torch.zeros((n_rays, src.shape[-1]), dtype=src.dtype, device=src.device)
    return out.index_add(0, ray_indices, src)


def _install_nerfacc_stand_in() -> None:
    """gsplat's ``accumulate_2dgs`` imports nerfacc when called; give it the CPU versions above."""
    if "nerfacc" in sys.modules:
        return
    stand_in = types.ModuleType("nerfacc")
    stand_in.render_weight_from_alpha = _render_weight_from_alpha
    stand_in.accumulate_along_rays = _accumulate_along_rays
    sys.modules["nerfacc"] = stand_in


def _surfel_alpha(means2d, M, opacities, gid, px, py):
    """Alpha of surfels ``gid`` at pixel centres (px + 0.5, py + 0.5): gsplat's 2DGS ray-splat rule."""
    import torch

    x, y = px.float() + 0.5, py.float() + 0.5
    Mg = M[gid]
    h_u = -Mg[:, 0, :] + Mg[:, 2, :] * x[:, None]
    h_v = -Mg[:, 1, :] + Mg[:, 2, :] * y[:, None]
    p = torch.cross(h_u, h_v, dim=-1)
    on_plane = (p[:, 0] / p[:, 2]) ** 2 + (p[:, 1] / p[:, 2]) ** 2
    dx, dy = x - means2d[gid, 0], y - means2d[gid, 1]
    sigma = 0.5 * torch.minimum(on_plane, 2 * (dx * dx + dy * dy))
    alpha = torch.clamp_max(opacities[gid] * torch.exp(-sigma), 0.999)
    return torch.where(sigma >= 0, alpha, torch.zeros_like(alpha))


def _candidate_boxes(means2d, radii, width, height):
    """Per visible surfel: its id, first pixel column and row, box width and pixel count (boxes clipped to
    the image; empty ones dropped)."""
    import torch

    ids = torch.nonzero((radii > 0).all(-1)).squeeze(1)
    m, r = means2d[ids], radii[ids].float()
    x0 = torch.clamp(torch.ceil(m[:, 0] - r[:, 0] - 0.5), 0, width).long()
    x1 = torch.clamp(torch.floor(m[:, 0] + r[:, 0] - 0.5) + 1, 0, width).long()
    y0 = torch.clamp(torch.ceil(m[:, 1] - r[:, 1] - 0.5), 0, height).long()
    y1 = torch.clamp(torch.floor(m[:, 1] + r[:, 1] - 0.5) + 1, 0, height).long()
    box_w, count = (x1 - x0).clamp(min=0), (x1 - x0).clamp(min=0) * (y1 - y0).clamp(min=0)
    keep = count > 0
    return ids[keep], x0[keep], y0[keep], box_w[keep], count[keep]


def _intersections(means2d, radii, depths, M, opacities, width, height, chunk=4_000_000):
    """(surfel ids, pixel ids) of the pairs to composite, sorted by pixel, then front to back; chunked
    over surfels so that at most ~``chunk`` candidate pairs are alive at once."""
    import torch

    with torch.no_grad():
        n = means2d.shape[0]
        rank = torch.empty(n, dtype=torch.long)
        rank[torch.argsort(depths)] = torch.arange(n)
        ids, x0, y0, box_w, count = _candidate_boxes(means2d, radii, width, height)
        ends = torch.cumsum(count, 0)
        gs, pix, alphas = [], [], []
        first = 0
        while first < len(ids):
            base = int(ends[first - 1]) if first else 0
            last = max(int(torch.searchsorted(ends, base + chunk, right=True)), first + 1)
            local = torch.repeat_interleave(torch.arange(first, last), count[first:last])
            k = torch.arange(base, int(ends[last - 1])) - (ends[local] - count[local])
            px, py, gid = x0[local] + k % box_w[local], y0[local] + k // box_w[local], ids[local]
            alpha = _surfel_alpha(means2d, M, opacities, gid, px, py)
            hit = alpha >= ALPHA_MIN
            gs.append(gid[hit])
            pix.append((py * width + px)[hit])
            alphas.append(alpha[hit])
            first = last
        gs, pix, alpha = torch.cat(gs), torch.cat(pix), torch.cat(alphas)
        order = torch.argsort(pix * n + rank[gs])
        gs, pix, alpha = gs[order], pix[order], alpha[order]
        alive = _exclusive_transmittance(alpha, pix) * (1 - alpha) > TRANSMITTANCE_MIN
        return gs[alive], pix[alive]


def render(means, quats, scales, opacities, colors, viewmat, K, width, height):
    """The peer's image [H, W, 3] of surfels (means [N, 3], quats [N, 4] wxyz, scales [N, 3] with the third
    0, opacities [N], colors [N, 3]) on a black background; differentiable where gsplat's torch path is."""
    import torch
    from gsplat.cuda._torch_impl_2dgs import _fully_fused_projection_2dgs, accumulate_2dgs

    radii, means2d, depths, M, normals = _fully_fused_projection_2dgs(means, quats, scales, viewmat[None],
                                                                      K[None], width, height)
    means2d, depths, M, normals, radii = means2d[0], depths[0], M[0], normals[0], radii[0]
    gs, pix = _intersections(means2d.detach(), radii, depths.detach(), M.detach(), opacities.detach(),
                             width, height)
    image, _, _ = accumulate_2dgs(means2d[None], M[None], opacities[None], colors[None], normals[None], gs, pix,
                                  torch.zeros_like(gs), width, height)
    return image[0]  # black background: nothing to add for (1 - alpha)
