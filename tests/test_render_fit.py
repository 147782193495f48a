"""Fitting through the WGSL renderer alone: Adam on a perturbed copy of a 1,000-surfel scene recovers
the target image (the end-to-end check that forward and backward agree in practice)."""

from __future__ import annotations

import pytest
import torch
from render_helpers import default_camera, torch_scene

from gma.render import rasterize

pytestmark = pytest.mark.gpu


def psnr(a: torch.Tensor, b: torch.Tensor) -> float:
    return float(-10 * torch.log10(((a - b) ** 2).mean()))


@pytest.mark.slow
def test_adam_recovers_perturbed_scene(gpu):
    cam = default_camera(64, 64)
    view, K = torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K)
    scene = torch_scene(1000, seed=21, scale_range=(0.03, 0.12))
    bg = torch.tensor([0.1, 0.1, 0.1])
    with torch.no_grad():
        target = rasterize(*(scene[k] for k in ("means", "quats", "scales", "opacities", "colors")),
                           view, K, 64, 64, bg, ctx=gpu).color
    g = torch.Generator().manual_seed(1)
    means = (scene["means"] + 0.05 * torch.randn(scene["means"].shape, generator=g)).requires_grad_(True)
    quats = (scene["quats"] + 0.1 * torch.randn(scene["quats"].shape, generator=g)).requires_grad_(True)
    log_scales = (scene["scales"].log() + 0.2 * torch.randn(scene["scales"].shape, generator=g)).requires_grad_(True)
    o = scene["opacities"].clamp(0.02, 0.98)
    logit_o = (torch.log(o / (1 - o)) + 0.5 * torch.randn(o.shape, generator=g)).requires_grad_(True)
    logit_c = torch.randn(scene["colors"].shape, generator=g).requires_grad_(True)  # colours start random
    opt = torch.optim.Adam([{"params": [means], "lr": 2e-3}, {"params": [quats, log_scales], "lr": 1e-2},
                            {"params": [logit_o, logit_c], "lr": 5e-2}])

    def render():
        return rasterize(means, quats, log_scales.exp(), torch.sigmoid(logit_o), torch.sigmoid(logit_c),
                         view, K, 64, 64, bg, ctx=gpu).color

    start = psnr(render().detach(), target)
    assert start < 25, f"the perturbation should be substantial (start PSNR {start:.1f} dB)"
    for _ in range(150):
        loss = ((render() - target) ** 2).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    final = psnr(render().detach(), target)
    assert final > 30, f"PSNR {start:.1f} -> {final:.1f} dB after 150 steps"
