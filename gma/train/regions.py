"""Scores by body region: where a held-out frame goes wrong matters as much as by how much (a washed-out
face or see-through hands spoil an avatar that scores well over the image).

Each pixel of a frame gets the region of the body face it shows: a face-ID render of the posed body mesh
(:class:`gma.render.face_id.FaceIdRenderer`) at the frame's camera, its faces mapped to ``REGION_ORDER``
through the body's coarse regions. The person's mask pixels that no body face covers (loose clothes,
hair) count as ``rest``. ``face`` is the body's head region: from the views a person is filmed from it is
mostly the face.

Per region, :func:`region_metrics` gives PSNR and SSIM over the region's pixels, and the mean rendered
opacity inside the target mask there (1 where the avatar is solid, lower where the background shows
through). A region that no pixel of the frame shows is reported as absent (None), never as NaN, and
:func:`mean_by_region` averages over the frames that show it.
"""

from __future__ import annotations

import math

import numpy as np
import torch

from gma.core.camera import Camera
from gma.train.metrics import ssim_map

__all__ = ["REGION_ORDER", "RegionMapper", "face_region_codes", "mean_by_region", "region_metrics"]

# Region names in the order of their codes; a face in none of the named body regions is "rest".
REGION_ORDER = ("rest", "face", "hands", "arms")
_BODY_REGION = {"face": "head", "hands": "hands", "arms": "arms"}


def face_region_codes(body) -> np.ndarray:
    """[F] int code of each body face's region (an index into ``REGION_ORDER``)."""
    codes = np.zeros(body.num_faces, np.int64)
    for code, name in enumerate(REGION_ORDER):
        if name in _BODY_REGION:
            codes[body.region_mask(_BODY_REGION[name]).numpy().astype(bool)] = code
    return codes


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
        return {name: code == i for i, name in enumerate(REGION_ORDER)}


def _masked_psnr(a: torch.Tensor, b: torch.Tensor, m: torch.Tensor) -> float:
    mse = float(((a - b) ** 2)[m].mean())
    return 99.0 if mse <= 1e-10 else 10 * math.log10(1.0 / mse)


def region_metrics(render: torch.Tensor, target: torch.Tensor, alpha: torch.Tensor, mask: torch.Tensor,
                   regions: dict[str, np.ndarray]) -> dict[str, dict[str, float | None]]:
    """{region: {"psnr", "ssim", "opacity"}} of [H, W, 3] ``render`` against ``target`` over each region's
    pixels; ``opacity`` is the mean rendered ``alpha`` [H, W, 1] inside ``mask`` [H, W, 1] > 0.5 there.
    None for what the frame does not show."""
    similarity = ssim_map(render, target)
    person = mask[..., 0] > 0.5
    out = {}
    for name, where in regions.items():
        m = torch.from_numpy(where)
        inside = m & person
        shown = bool(m.any())
        out[name] = {"psnr": _masked_psnr(render, target, m) if shown else None,
                     "ssim": float(similarity[m].mean()) if shown else None,
                     "opacity": float(alpha[..., 0][inside].mean()) if bool(inside.any()) else None}
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
