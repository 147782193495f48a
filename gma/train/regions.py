"""Scores by body region: where a held-out frame goes wrong matters as much as by how much (a washed-out
face or see-through hands spoil an avatar that scores well over the image).

Each pixel of a frame gets the region of the body face it shows: a face-ID render of the posed body mesh
(:class:`gma.render.face_id.FaceIdRenderer`) at the frame's camera, its faces mapped to ``BODY_REGIONS``
through the body's coarse regions (``legs`` includes the feet). The person's mask pixels that no body
face covers (loose clothes, hair) count as ``rest``. ``face`` is the body's head region: from the views a
person is filmed from it is mostly the face.

One more region crosses the others: ``edge``, the pixels within ``EDGE_PX`` of the boundary of the
person's mask, on either side. A misplaced limb or a loose outline shows there first, so its score
separates "the outline is wrong" from "the texture inside is wrong".

Per region, :func:`region_metrics` gives PSNR and SSIM over the region's pixels; ``error``, the region's
share of the frame's squared colour error (a region scoring low PSNR over a few pixels may still cost the
image little: this says where a better avatar would gain); and two measures of how solid the avatar is
inside the person's mask (``mask`` > 0.5) there:

- ``opacity``: the mean rendered alpha (1 where the avatar is solid, lower where the background shows
  through);
- ``coverage``: how much of the target's own soft mask the render covers, ``Σ min(alpha, m) / Σ m``. The
  target's outline is soft (a pixel the person half covers has ``m`` = 0.5–0.9), so a render that matches
  it exactly has an opacity well below 1 on the outline and a coverage of 1; a see-through limb
  (``alpha`` 0.5 where ``m`` = 1) lowers both alike. Regions that lie mostly on the outline (``rest``,
  ``edge``) need this one to tell "see-through" from "anti-aliased".

A region that no pixel of the frame shows is reported as absent (None), never as NaN, and
:func:`mean_by_region` averages over the frames that show it.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from gma.core.camera import Camera
from gma.train.metrics import ssim_map

__all__ = ["BODY_REGIONS", "EDGE_PX", "REGION_ORDER", "RegionMapper", "edge_band", "face_region_codes",
           "mean_by_region", "region_metrics"]

# Region names of the body, in the order of their codes; a face in none of the named body regions is "rest".
BODY_REGIONS = ("rest", "face", "hands", "arms", "torso", "legs")
# Every region a frame is scored on: the body's, then the band along the mask's outline.
REGION_ORDER = (*BODY_REGIONS, "edge")
_BODY_REGION = {"face": ("head",), "hands": ("hands",), "arms": ("arms",), "torso": ("torso",),
                "legs": ("legs", "feet")}
# Half-width of the outline band in pixels: wide enough to hold a limb drawn a little off its place at the
# evaluation's size, narrow enough to leave the texture inside the person out.
EDGE_PX = 2


def face_region_codes(body) -> np.ndarray:
    """[F] int code of each body face's region (an index into ``BODY_REGIONS``)."""
    codes = np.zeros(body.num_faces, np.int64)
    for code, name in enumerate(BODY_REGIONS):
        for part in _BODY_REGION.get(name, ()):
            if part in body.regions:  # a body without feet (or any part) leaves those faces to the rest
                codes[body.region_mask(part).numpy().astype(bool)] = code
    return codes


def edge_band(person: np.ndarray, width: int = EDGE_PX) -> np.ndarray:
    """[H, W] bool: the pixels within ``width`` pixels (chessboard distance) of the boundary of the bool
    mask ``person`` [H, W], inside or outside it. Empty when the mask is empty or fills the frame."""
    from scipy.ndimage import binary_dilation, binary_erosion

    if not person.any() or person.all():
        return np.zeros_like(person, dtype=bool)
    square = np.ones((3, 3), bool)
    grown = binary_dilation(person, square, iterations=width)
    # border_value=1: the frame's border is not an outline (a person cut off by the frame edge)
    shrunk = binary_erosion(person, square, iterations=width, border_value=1)
    return grown & ~shrunk


class RegionMapper:
    """Region maps of frames: ``maps(vertices, w2c, K, mask)`` -> {region: [H, W] bool}."""

    def __init__(self, ctx, body):
        from gma.render.face_id import FaceIdRenderer

        self.codes = face_region_codes(body)
        self.ids = FaceIdRenderer(ctx, body.faces.numpy())

    def maps(self, vertices: torch.Tensor, w2c: torch.Tensor, K: torch.Tensor, mask: torch.Tensor
             ) -> dict[str, np.ndarray]:
        """``vertices`` [V, 3] posed body; ``w2c`` [4, 4], ``K`` [3, 3] of a ``mask`` [H, W, 1] frame."""
        h, w = mask.shape[:2]
        camera = Camera(np.asarray(w2c, np.float32), np.asarray(K, np.float32), w, h)
        shown = self.ids.render(np.asarray(vertices, np.float32), camera).ids
        code = np.where(shown >= 0, self.codes[np.clip(shown, 0, None)], -1)
        person = mask[..., 0].numpy() > 0.5
        code[(code < 0) & person] = 0  # the person's pixels off the body mesh: clothes, hair
        return {**{name: code == i for i, name in enumerate(BODY_REGIONS)}, "edge": edge_band(person)}


def _psnr_of(squared: torch.Tensor, channels: int) -> float:
    """PSNR of pixels whose squared colour errors, summed over ``channels``, are ``squared`` [N]."""
    mse = float(squared.mean()) / channels
    return 99.0 if mse <= 1e-10 else 10 * math.log10(1.0 / mse)


def region_metrics(render: torch.Tensor, target: torch.Tensor, alpha: torch.Tensor, mask: torch.Tensor,
                   regions: dict[str, np.ndarray]) -> dict[str, dict[str, float | None]]:
    """{region: {"psnr", "ssim", "error", "opacity", "coverage"}} of [H, W, 3] ``render`` against ``target``
    over each region's pixels; ``error`` is the region's share of the frame's squared error (0 for a frame
    without error), ``opacity`` the mean rendered ``alpha`` [H, W, 1] inside ``mask`` [H, W, 1] > 0.5
    there, ``coverage`` the share of the soft mask there that ``alpha`` covers (module docstring). None for
    what the frame does not show."""
    similarity = ssim_map(render, target)
    squared = ((render - target) ** 2).sum(-1)  # [H, W]: every region's PSNR and error share read it
    total = float(squared.sum())
    soft = mask[..., 0].clamp(0, 1)
    person = soft > 0.5
    covered = torch.minimum(alpha[..., 0], soft)
    out = {}
    for name, where in regions.items():
        m = torch.from_numpy(where)
        inside = m & person
        shown, solid = bool(m.any()), bool(inside.any())
        out[name] = {"psnr": _psnr_of(squared[m], render.shape[-1]) if shown else None,
                     "ssim": float(similarity[m].mean()) if shown else None,
                     "error": (float(squared[m].sum()) / total if total > 0 else 0.0) if shown else None,
                     "opacity": float(alpha[..., 0][inside].mean()) if solid else None,
                     "coverage": float(covered[inside].sum() / soft[inside].sum()) if solid else None}
    return out


def mean_by_region(rows: list[dict[str, dict[str, float | None]]]) -> dict[str, dict[str, float | None]]:
    """Per region and score, the mean over the frames that show the region (None where none does), and
    ``frames``: how many do."""
    out = {}
    for name in rows[0] if rows else ():
        scores = {}
        for key in rows[0][name]:
            values = [r[name][key] for r in rows if r[name][key] is not None]
            scores[key] = float(np.mean(values)) if values else None
        scores["frames"] = sum(r[name]["psnr"] is not None for r in rows)
        out[name] = scores
    return out
