"""Bad inputs to gma.render.rasterize give errors that name the argument and the problem."""

from __future__ import annotations

import numpy as np
import pytest
import torch
from render_helpers import default_camera, torch_scene

from gma.render import rasterize


def args(n=4, **override):
    s = torch_scene(n)
    cam = default_camera(16, 16)
    a = dict(means=s["means"], quats=s["quats"], scales=s["scales"], opacities=s["opacities"],
             colors=s["colors"], viewmat=torch.from_numpy(cam.viewmat), K=torch.from_numpy(cam.K),
             width=16, height=16)
    a.update(override)
    return a


def nan_at(t, idx):
    t = t.clone()
    t[idx] = float("nan")
    return t


@pytest.mark.parametrize("override,match", [
    (lambda a: {"means": nan_at(a["means"], (1, 2))}, r"means holds 1 non-finite.*\[1, 2\]"),
    (lambda a: {"colors": nan_at(a["colors"], (0, 0))}, r"colors holds 1 non-finite"),
    (lambda a: {"scales": a["scales"].index_put((torch.tensor([2]), torch.tensor([1])), torch.tensor(float("inf")))},
     r"scales holds 1 non-finite.*\[2, 1\]"),
    (lambda a: {"opacities": torch.tensor([float("inf"), -float("inf"), 0.5, 0.5])},   # the sum is NaN
     r"opacities holds 2 non-finite.*\[0\]"),
    (lambda a: {"viewmat": nan_at(a["viewmat"], (0, 3))}, r"viewmat holds"),
    (lambda a: {"means": a["means"][:, :2]}, r"means must have shape \[\*, 3\], got \[4, 2\]"),
    (lambda a: {"quats": a["quats"][:3]}, r"quats must have shape \[4, 4\], got \[3, 4\]"),
    (lambda a: {"scales": a["scales"][:, :1]}, r"scales must have shape \[4, 2\]"),
    (lambda a: {"opacities": a["opacities"][:, None].repeat(1, 2)}, r"opacities must have shape \[4\]"),
    (lambda a: {"colors": a["colors"][:, :0]}, r"colors must have 1 to 64 channels"),
    (lambda a: {"K": a["K"][:2]}, r"K must have shape \[3, 3\]"),
    (lambda a: {"width": 0}, r"width must be a positive integer"),
    (lambda a: {"height": 12.5}, r"height must be a positive integer"),
    (lambda a: {"scales": -a["scales"]}, r"scales must be >= 0"),
    (lambda a: {"opacities": a["opacities"] + 2}, r"opacities must lie in \[0, 1\]"),
    (lambda a: {"quats": torch.zeros(4, 4)}, r"quats has zero-length rows"),
    (lambda a: {"quats": a["quats"].index_put((torch.tensor([3]),), torch.full((4,), 1e-30))},
     r"quats has zero-length rows"),   # |q|^2 underflows to 0 in float32: no direction
    (lambda a: {"means": torch.zeros(0)}, r"means must have shape \[\*, 3\], got \[0\]"),
])
def test_bad_input_messages(override, match):
    a = args()
    a.update(override(a))
    with pytest.raises(ValueError, match=match):
        rasterize(**a)


def test_type_errors():
    a = args()
    a["means"] = a["means"].to(torch.int64)
    with pytest.raises(TypeError, match="means must be a floating-point tensor"):
        rasterize(**a)
    a = args()
    a["colors"] = [[0.0, 0.0, 0.0]] * 4
    with pytest.raises(TypeError, match="colors must be a torch tensor"):
        rasterize(**a)


def test_background_checked():
    with pytest.raises(ValueError, match=r"background must have shape \[3\]"):
        rasterize(**args(), background=torch.zeros(4))


@pytest.mark.gpu
def test_empty_scene_renders_background(gpu):
    a = args(0)
    out = rasterize(**a, background=torch.tensor([0.25, 0.5, 0.75]), ctx=gpu)
    assert out.color.shape == (16, 16, 3)
    assert torch.allclose(out.color, torch.tensor([0.25, 0.5, 0.75]).expand(16, 16, 3))
    assert float(out.alpha.abs().max()) == 0.0


def test_zero_length_quaternion_rows_found_exactly():
    """The quaternion check tests only rows whose components are all tiny, exactly as float32 squares them."""
    from gma.render.validate import _zero_length_rows

    q = np.random.default_rng(0).normal(size=(1000, 4)).astype(np.float32)
    assert not _zero_length_rows(q)
    for row, zero in (([0, 0, 0, 0], True), ([1e-23, 0, 0, 0], True),   # squares underflow to 0
                      ([1e-19, 0, 0, 0], False), ([1e-18, 1e-18, 0, 0], False), ([1, 0, 0, 0], False)):
        bad = q.copy()
        bad[7] = row
        assert _zero_length_rows(bad) == zero, row
    assert not _zero_length_rows(np.zeros((0, 4), np.float32))


def test_values_rejected_while_projecting_leave_the_renderer_as_it_was(gpu, monkeypatch):
    # The public call checks the surfels' values after projection is submitted (SurfelRasterizer.forward's
    # while_projecting): nothing after projection runs on them, and no hint grows from them.
    from gma.render.api import rasterizer_for

    a = args(n=64)
    good = rasterize(**a, ctx=gpu).color
    rast = rasterizer_for(gpu)
    hints = (rast.isect_capacity_hint, rast.depth_bits_hint)
    after_projection = []
    rest = rast._sort_bin_rasterize
    monkeypatch.setattr(rast, "_sort_bin_rasterize", lambda *x: after_projection.append(1) or rest(*x))
    bad = a["scales"].clone()
    bad[5, 0] = float("nan")
    with pytest.raises(ValueError, match=r"scales holds 1 non-finite.*\[5, 0\]"):
        rasterize(**dict(a, scales=bad), ctx=gpu)
    assert not after_projection and (rast.isect_capacity_hint, rast.depth_bits_hint) == hints
    assert torch.equal(rasterize(**a, ctx=gpu).color, good) and after_projection
