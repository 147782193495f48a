"""Per-face part labels and coarse garment-selection regions.

Fine labels come from a backend's own segmentation (Anny: its UV-space body-part image). Coarse regions
(``REGIONS``) come from the skinning: each face's dominant bone (largest summed weight over its three
vertices), mapped through bone-name rules, refined by the fine labels where those are more precise
(head, hands, feet). Regions may overlap (``upper_body`` contains ``arms``).
"""

from __future__ import annotations

import re

import torch

__all__ = ["REGIONS", "dominant_bone_per_face", "regions_from_bones"]

REGIONS = ("head", "torso", "arms", "hands", "legs", "feet", "upper_body", "lower_body")

# Bone name patterns (Anny's makehuman-style names first, SMPL-X joint names after) → base region.
# Order matters: the first matching rule wins.
_BONE_RULES: tuple[tuple[str, str], ...] = (
    (r"^(neck|head|jaw|eye|tongue|special|oris|levator|orbicularis|oculi|temporalis|risorius)", "head"),
    (r"^(left_eye|right_eye)", "head"),
    (r"^(wrist|finger|metacarpal|thumb)", "hands"),
    (r"^(left_|right_)(wrist|index|middle|pinky|ring|thumb)", "hands"),
    (r"^(toe|foot)", "feet"),
    (r"^(left_|right_)(ankle|foot)", "feet"),
    (r"^(upperleg|lowerleg|(left_|right_)(hip|knee))", "legs"),
    (r"^(shoulder|upperarm|lowerarm|(left_|right_)(shoulder|elbow))", "arms"),
    (r"^(root|pelvis)", "hips"),
    (r"^(spine05|spine04|spine1$)", "waist"),
    (r"^(spine|clavicle|breast|(left_|right_)collar)", "chest"),
)

# Where faces go that the bones assign to an overridden region but the override does not cover.
_FALLBACK = {"head": "chest", "hands": "arms", "feet": "legs"}


def _bone_region(name: str) -> str:
    for pattern, region in _BONE_RULES:
        if re.match(pattern, name):
            return region
    return "chest"


def dominant_bone_per_face(faces: torch.Tensor, skin_indices: torch.Tensor, skin_weights: torch.Tensor,
                           num_bones: int) -> torch.Tensor:
    """[F] index of the bone with the largest summed weight over each face's corners."""
    nv = skin_indices.shape[0]
    dense = torch.zeros(nv, num_bones).scatter_add_(1, skin_indices.long(), skin_weights.float())
    return (dense[faces[:, 0]] + dense[faces[:, 1]] + dense[faces[:, 2]]).argmax(1)


def regions_from_bones(
    faces: torch.Tensor,
    skin_indices: torch.Tensor,
    skin_weights: torch.Tensor,
    bone_names: tuple[str, ...],
    overrides: dict[str, torch.Tensor] | None = None,
) -> dict[str, torch.Tensor]:
    """Coarse regions name → [F] bool. ``overrides`` (e.g. the segmentation's head / hands / feet masks)
    replace the bone-derived base region of the same name, and are removed from the others so the base
    regions stay disjoint.

    Hips (root/pelvis) and the lowest spine bones ("waist") count as lower body (where trousers sit);
    the chest, collar bones and arms as upper body.
    """
    dominant = dominant_bone_per_face(faces, skin_indices, skin_weights, len(bone_names))
    base_of_bone = [_bone_region(n) for n in bone_names]
    names = sorted(set(base_of_bone) | set(overrides or {}))
    lookup = torch.tensor([names.index(b) for b in base_of_bone])
    face_base = lookup[dominant]
    base = {n: face_base == names.index(n) for n in names}
    for name, mask in (overrides or {}).items():
        # Faces the bones put in this region but the override does not (the neck under the head, the
        # wrist above the hand) go to the neighbouring region on the limb's side.
        leftover = base.get(name, torch.zeros_like(mask)) & ~mask
        fallback = _FALLBACK.get(name, "chest")
        base[fallback] = base.get(fallback, torch.zeros_like(mask)) | leftover
        for other in base:
            base[other] = base[other] & ~mask
        base[name] = mask.clone()
    empty = torch.zeros(faces.shape[0], dtype=torch.bool)

    def get(n):
        return base.get(n, empty)

    torso = get("chest") | get("waist") | get("hips")
    return {
        "head": get("head"),
        "torso": torso,
        "arms": get("arms"),
        "hands": get("hands"),
        "legs": get("legs"),
        "feet": get("feet"),
        "upper_body": get("chest") | get("arms"),
        "lower_body": get("waist") | get("hips") | get("legs"),
    }
