"""Posing a decoded avatar in torch (the differentiable path training uses), and the mapping from a
sequence's per-frame body arrays to ``BodyModel`` parameters."""

from __future__ import annotations

import numpy as np
import torch

from gma.avatar.model import DecodedAvatar
from gma.body.placement import place_surfels
from gma.body.skinning import linear_blend_skinning

__all__ = ["PosedSurfels", "backfacing_mask", "face_away_cosine", "frame_params", "pose_surfels"]


def frame_params(model: str, arrays: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
    """``BodyModel`` parameters of one frame from a sequence's ``body.frame(i)`` arrays (anny: pose,
    phenotype, facial_actions; smplx: betas, the axis-angle blocks, expression, transl)."""
    t = {k: torch.as_tensor(np.asarray(v), dtype=torch.float32) for k, v in arrays.items()
         if np.asarray(v).dtype.kind in "fiu"}
    if model == "anny":
        out = {"pose": t["pose"], "shape": t["phenotype"]}
        if "facial_actions" in t:
            out["expression"] = t["facial_actions"]
        return out
    if model == "smplx":
        pose = torch.cat([t["global_orient"].reshape(1, 3), t["body_pose"].reshape(21, 3),
                          t.get("jaw_pose", torch.zeros(3)).reshape(1, 3),
                          t.get("leye_pose", torch.zeros(3)).reshape(1, 3),
                          t.get("reye_pose", torch.zeros(3)).reshape(1, 3),
                          t.get("left_hand_pose", torch.zeros(45)).reshape(15, 3),
                          t.get("right_hand_pose", torch.zeros(45)).reshape(15, 3)], 0)
        out = {"pose": pose, "shape": t["betas"], "transl": t["transl"]}
        if "expression" in t:
            out["expression"] = t["expression"]
        return out
    raise ValueError(f"fitting supports 'anny' and 'smplx' body parameters, not {model!r} "
                     "(convert SMPL sequences to SMPL-X first)")


class PosedSurfels(dict):
    """means [N, 3], quats [N, 4], scales [N, 2], colors [N, 3], opacities [N], vertices [V, 3] (posed
    morphed mesh), rest [V, 3] (morphed canonical mesh), and, when surfels were culled, rows [N] (the
    decoded avatar's surfels these are). A dict so it can be filtered by a mask."""


def pose_surfels(decoded: DecodedAvatar, faces: torch.Tensor, skin_indices: torch.Tensor,
                 skin_weights: torch.Tensor, rest_vertices: torch.Tensor,
                 bone_transforms: torch.Tensor, visible_from: torch.Tensor | None = None) -> PosedSurfels:
    """Morph, skin and place the decoded surfels for one frame (differentiable w.r.t. ``decoded``).

    rest_vertices: [V, 3] the body's rest vertices of this frame (shape + expression, no morph);
    bone_transforms: [J, 4, 4] rest->posed; visible_from: a world->camera matrix [4, 4] (optional):
    the surfels on faces turned away from that camera (``backfacing_mask``) are dropped before they
    are placed, which saves placing (and differentiating) the half of them a render would drop.
    """
    rest = rest_vertices + decoded.vertex_offsets
    verts = linear_blend_skinning(rest, skin_indices, skin_weights, bone_transforms)
    binding, colors, opacities, extra = decoded.binding, decoded.colors, decoded.opacities, {}
    if visible_from is not None:
        rows = backfacing_mask(verts, faces, binding.face_id, visible_from).nonzero().squeeze(1)
        binding, colors, opacities, extra = binding.select(rows), colors[rows], opacities[rows], {"rows": rows}
    means, quats, scales = place_surfels(verts, faces, binding)
    return PosedSurfels(means=means, quats=quats, scales=scales, colors=colors, opacities=opacities,
                        vertices=verts, rest=rest, **extra)


def backfacing_mask(vertices: torch.Tensor, faces: torch.Tensor, face_id: torch.Tensor, viewmat: torch.Tensor,
                    margin: float = 0.25) -> torch.Tensor:
    """[N] bool: True for surfels worth rendering from this camera — those whose face does not point
    clearly away from it (cos > ``margin`` away). A back-facing face of a closed body is hidden behind
    front-facing ones, so dropping it changes only what shows through silhouettes; on a CPU rasteriser it
    halves the work of every training step."""
    keep_face = face_away_cosine(vertices, faces, viewmat) < margin
    return keep_face[face_id]


@torch.no_grad()
def face_away_cosine(vertices: torch.Tensor, faces: torch.Tensor, viewmat: torch.Tensor) -> torch.Tensor:
    """[F] cosine between each face's normal and the direction from the camera (world->camera ``viewmat``)
    to the face's centre: 1 for a face turned straight away from the camera, -1 for one facing it."""
    tri = vertices[faces]  # [F, 3, 3]
    n = torch.nn.functional.normalize(torch.linalg.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), dim=-1)
    r, t = viewmat[:3, :3], viewmat[:3, 3]
    eye = -r.T @ t
    to_face = torch.nn.functional.normalize(tri.mean(1) - eye, dim=-1)
    return (n * to_face).sum(-1)
