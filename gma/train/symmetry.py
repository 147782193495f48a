"""A left-right symmetry prior on the avatar's texture features (``gma fit --symmetry W``), for clips
that show one side of the person less than the other: a single turn that stops short of the start, a
person filmed mostly from one side.

The body's rest mesh is mirror-symmetric about its x = 0 plane (Anny's exactly, at any phenotype), so
every face has a mirror face. The prior pulls each face's texture features ``f_tex`` toward those of its
mirror face, in proportion to how much less the training frames show it than its mirror
(``coverage_weights``): a side the clip shows well learns from its pictures alone and is not blurred
toward the other, and a clip that shows both sides alike gets almost no pull, so a person who is not
symmetric (a logo on one side of a shirt) keeps the difference where the pictures show it.
"""

from __future__ import annotations

import torch

from gma.avatar.posing import face_away_cosine
from gma.body.geometry import mirror_faces
from gma.body.skinning import linear_blend_skinning

__all__ = ["DEAD_ZONE", "SymmetryPrior", "coverage_weights", "face_coverage"]


@torch.no_grad()
def face_coverage(frames, body) -> torch.Tensor:
    """[F] how much of each face the training frames show: the mean over frames of the cosine between
    the posed face's normal and the direction to the camera, 0 when it faces away. Occlusion is ignored
    (an arm in front of the torso): this measures which side of the body the camera went round."""
    total = torch.zeros(len(body.faces))
    for t in range(len(frames)):
        verts = linear_blend_skinning(frames.rest[t], body.skin_indices, body.skin_weights, frames.bones[t])
        total += (-face_away_cosine(verts, body.faces, frames.w2c[t])).clamp_min(0.0)
    return total / max(len(frames), 1)


# Faces seen at least 80 % as much as their mirror are left to their pictures: a clip of a whole turn still
# sees one side a little less here and there (the person turns unevenly), and pulling those faces cost
# 0.13 dB on the iPER clip with every fourth frame held out; with this margin 0.03, and the unseen side of
# the stopped-short turn gained as much as without it (docs/fitting.md).
DEAD_ZONE = 0.2


def coverage_weights(coverage: torch.Tensor, mirror: torch.Tensor, dead_zone: float = DEAD_ZONE) -> torch.Tensor:
    """[F] in [0, 1]: how much less a face is seen than its mirror, the shortfall s = 1 - coverage / (the
    mirror face's coverage) mapped through the dead zone: (s - dead_zone) / (1 - dead_zone), 0 below it
    and where a face is seen at least as much as its mirror. A face the clip never shows whose mirror it
    does show gets 1."""
    other = coverage[mirror]
    shortfall = torch.where(other > coverage, 1.0 - coverage / other.clamp_min(1e-8), torch.zeros_like(coverage))
    return ((shortfall - dead_zone) / (1.0 - dead_zone)).clamp(0.0, 1.0)


class SymmetryPrior:
    """``prior(f_tex)``: the mean over faces of weight × mean squared difference between a face's
    texture features and its mirror face's, the mirror's held fixed (the better-seen side teaches the
    other, not the reverse)."""

    def __init__(self, frames, body):
        self.mirror = mirror_faces(frames.rest[0], body.faces)
        self.coverage = face_coverage(frames, body)
        self.weights = coverage_weights(self.coverage, self.mirror)

    def summary(self) -> dict:
        """What the prior acts on: the share of faces it pulls at all, and their mean weight."""
        pulled = self.weights > 0
        return {"faces_pulled": round(float(pulled.float().mean()), 4),
                "mean_weight_pulled": round(float(self.weights[pulled].mean()), 4) if bool(pulled.any()) else 0.0}

    def __call__(self, f_tex: torch.Tensor) -> torch.Tensor:
        diff = f_tex - f_tex[self.mirror].detach()
        return (self.weights * diff.pow(2).mean(-1)).mean()
