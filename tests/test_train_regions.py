"""Per-region scores of ``gma eval``: region maps from the posed body, PSNR / SSIM / opacity over a
region's pixels, and absent regions reported as None, never NaN."""

from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from gma.train.metrics import ssim, ssim_map
from gma.train.regions import (
    BODY_REGIONS,
    REGION_ORDER,
    RegionMapper,
    edge_band,
    face_region_codes,
    mean_by_region,
    region_metrics,
)


def _images(h=24, w=32, seed=0):
    g = torch.Generator().manual_seed(seed)
    target = torch.rand(h, w, 3, generator=g)
    render = target.clone()
    return render, target


def test_region_scores_follow_their_own_pixels():
    render, target = _images()
    render[:, 16:] += 0.1  # only the right half is off, by 0.1 in every channel
    alpha = torch.ones(24, 32, 1)
    alpha[:, 16:] = 0.5  # and half transparent there
    mask = torch.ones(24, 32, 1)
    left = np.zeros((24, 32), bool)
    left[:, :16] = True
    scores = region_metrics(render.clamp(max=2), target, alpha, mask, {"face": left, "hands": ~left})
    assert scores["face"]["psnr"] == 99.0 and scores["face"]["opacity"] == 1.0
    assert scores["hands"]["psnr"] == pytest.approx(20.0, abs=1e-3)  # 10 log10(1 / 0.1^2)
    assert scores["hands"]["opacity"] == pytest.approx(0.5)
    assert scores["hands"]["coverage"] == pytest.approx(0.5) and scores["face"]["coverage"] == 1.0
    assert scores["face"]["ssim"] > scores["hands"]["ssim"]
    assert scores["hands"]["error"] == pytest.approx(1.0) and scores["face"]["error"] == 0.0
    # A share of the frame's error, not of the region's: a region larger than where the error lies gets all
    # of it, a region beside it none, and a frame without error gives every region 0 (not 0 / 0).
    everywhere = np.ones((24, 32), bool)
    assert region_metrics(render, target, alpha, mask, {"rest": everywhere})["rest"]["error"] == pytest.approx(1.0)
    assert region_metrics(target, target, alpha, mask, {"rest": everywhere})["rest"]["error"] == 0.0


def test_coverage_tells_an_anti_aliased_outline_from_a_see_through_one():
    render, target = _images()
    mask = torch.zeros(24, 32, 1)
    mask[4:20, 4:28] = 1.0
    mask[4:20, 27] = 0.6  # the outline's column: the person covers 60 % of those pixels
    band = np.zeros((24, 32), bool)
    band[:, 26:29] = True
    exact = region_metrics(render, target, mask.clone(), mask, {"edge": band})["edge"]
    assert exact["coverage"] == pytest.approx(1.0)
    assert exact["opacity"] == pytest.approx(0.8)  # (1 + 0.6) / 2: below 1 though nothing is missing
    thin = region_metrics(render, target, mask * 0.5, mask, {"edge": band})["edge"]
    assert thin["coverage"] == pytest.approx(0.5) and thin["opacity"] == pytest.approx(0.4)
    fat = region_metrics(render, target, torch.ones(24, 32, 1), mask, {"edge": band})["edge"]
    assert fat["coverage"] == pytest.approx(1.0)  # more than the target's cover is not more coverage


def test_a_region_the_frame_does_not_show_is_absent_not_nan():
    render, target = _images()
    nowhere = np.zeros((24, 32), bool)
    outside_mask = np.zeros((24, 32), bool)
    outside_mask[0, 0] = True
    mask = torch.zeros(24, 32, 1)  # the person covers nothing: no opacity to average
    scores = region_metrics(render, target, torch.ones(24, 32, 1), mask, {"hands": nowhere, "face": outside_mask})
    assert scores["hands"] == {"psnr": None, "ssim": None, "error": None, "opacity": None, "coverage": None}
    assert scores["face"]["psnr"] == 99.0 and scores["face"]["opacity"] is None
    means = mean_by_region([scores, scores])
    assert means["hands"] == {"psnr": None, "ssim": None, "error": None, "opacity": None, "coverage": None,
                              "frames": 0}
    assert means["face"]["frames"] == 2
    assert not any(isinstance(v, float) and math.isnan(v) for r in means.values() for v in r.values())


def test_ssim_is_the_mean_of_its_map():
    render, target = _images(seed=1)
    render = (render + 0.05 * torch.randn(render.shape, generator=torch.Generator().manual_seed(2))).clamp(0, 1)
    assert float(ssim(render, target)) == pytest.approx(float(ssim_map(render, target).mean()), abs=1e-7)
    assert ssim_map(render, target).shape == (24, 32)


@pytest.mark.gpu
def test_region_map_of_the_body_from_the_front(gpu, anny_body):
    """The canonical body seen from the front: the head shows as face at the top, hands at the sides, and
    a person-mask pixel off the body counts as the rest."""
    from gma.core.camera import Camera

    codes = face_region_codes(anny_body)
    # every named body region has faces; "rest" (code 0) is only what no body face covers
    assert set(np.unique(codes)) == set(range(1, len(BODY_REGIONS)))
    rest = anny_body.rest_vertices(anny_body.canonical_params())
    lo, hi = rest.min(0).values.numpy(), rest.max(0).values.numpy()
    centre = (lo + hi) / 2
    up = np.zeros(3)
    up[2 if anny_body.up_axis == "z" else 1] = 1.0  # the world direction shown upwards
    forward = np.zeros(3)
    forward[1 if anny_body.up_axis == "z" else 2] = -1.0
    cam = Camera.look_at(centre - 4.0 * forward, centre, up=up, fov_y_deg=30, width=64, height=64)
    mask = torch.zeros(64, 64, 1)
    mask[0, 0] = 1.0
    maps = RegionMapper(gpu, anny_body).maps(rest, torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), mask)
    assert maps["rest"][0, 0]
    assert set(maps) == set(REGION_ORDER)
    for name in ("face", "hands", "arms", "torso", "legs", "rest"):
        assert maps[name].sum() > 0, name
    rows = {name: np.nonzero(maps[name].any(1))[0].mean() for name in ("face", "torso", "legs")}
    assert rows["face"] < rows["torso"] < rows["legs"]  # top to bottom (image y grows downwards)
    body = sum(maps[name].astype(int) for name in BODY_REGIONS)
    assert body.max() == 1  # the body regions share no pixel


def test_edge_band_straddles_the_outline():
    """A 4×4 square in a 12×12 frame: the band is the pixels within 1 px of its outline, 1 px out and
    1 px in (here all of the square but its middle 2×2), and nothing beyond."""
    person = np.zeros((12, 12), bool)
    person[4:8, 4:8] = True
    band = edge_band(person, width=1)
    expected = np.zeros((12, 12), bool)
    expected[3:9, 3:9] = True
    expected[5:7, 5:7] = False
    assert np.array_equal(band, expected)
    assert not edge_band(person, width=1)[0].any()


@pytest.mark.parametrize("fill", [False, True])
def test_edge_band_of_no_outline_is_empty(fill):
    """An empty mask, or one that fills the frame (a person cut off by every border), has no outline."""
    assert not edge_band(np.full((6, 6), fill)).any()


def test_edge_band_ignores_the_frame_border():
    """A person cut off by the bottom of the frame: the bottom row is not an outline."""
    person = np.zeros((10, 10), bool)
    person[5:, 3:7] = True
    band = edge_band(person, width=1)
    assert not band[9, 4:6].any() and band[9, 3] and band[5, 5]
