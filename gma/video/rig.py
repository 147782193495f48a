"""A thin adapter around the Anny model for fitting: differentiable rest model from a phenotype,
forward kinematics from per-bone rotations, and the named body points of ``gma.video.landmarks``.

Kept here rather than in ``gma.body`` because it exposes Anny internals the fit needs (bone heads,
the COCO keypoint regressor) and nothing else uses them yet.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import roma
import torch

from gma.body.skinning import linear_blend_skinning
from gma.video.landmarks import model_point_names

__all__ = ["FIT_BONES", "HAND_BONES", "AnnyRig", "RestModel"]

# Bones whose rotation the fit estimates (the rest keep Anny's rest orientation): the twist helpers
# (upperarm02, lowerarm02, upperleg02, lowerleg02), pelvis, shoulder01 and toes stay fixed — 2D and
# 3D landmarks do not constrain them.
FIT_BONES = (
    "root", "spine05", "spine04", "spine03", "spine02", "spine01", "neck01", "neck02", "head",
    "clavicle.L", "upperarm01.L", "lowerarm01.L", "wrist.L",
    "clavicle.R", "upperarm01.R", "lowerarm01.R", "wrist.R",
    "upperleg01.L", "lowerleg01.L", "foot.L", "upperleg01.R", "lowerleg01.R", "foot.R",
)
HAND_BONES = {s: tuple(f"finger{n}-{k}.{s}" for n in range(1, 6) for k in (1, 2, 3)) for s in ("L", "R")}

# Soft joint limits: the largest rotation (radians, any axis) a bone takes from Anny's rest pose before
# the limit term starts to cost. Per-axis limits would be tighter; these stop the grossest failures
# (a spine folded in half, a head turned backwards) without a learned pose prior.
ANGLE_LIMITS = {
    "spine": 0.35, "neck": 0.45, "head": 0.6, "clavicle": 0.35, "upperarm": 2.6, "lowerarm": 2.6,
    "wrist": 1.3, "upperleg": 2.0, "lowerleg": 2.6, "foot": 0.9, "finger": 1.7,
}


def angle_limit(bone: str) -> float:
    for prefix, lim in ANGLE_LIMITS.items():
        if bone.startswith(prefix):
            return lim
    return float("inf")


@dataclass
class RestModel:
    """Anny for one phenotype: rest_vertices [V, 3], rest_heads [J, 3], rest_poses [J, 4, 4] (metres)."""

    rest_vertices: torch.Tensor
    rest_heads: torch.Tensor
    rest_poses: torch.Tensor


class AnnyRig:
    """Posing and landmark points of an :class:`~gma.body.anny_body.AnnyBody` for the fit."""

    def __init__(self, body, fit_hands: bool = True):
        self.body = body
        self.model = body.anny_model
        self.names = body.bone_names
        bones = list(FIT_BONES) + (list(HAND_BONES["L"]) + list(HAND_BONES["R"]) if fit_hands else [])
        self.fit_bones = tuple(bones)
        self.fit_index = torch.tensor([body.bone_index(b) for b in bones])
        self.limits = torch.tensor([angle_limit(b) for b in bones[1:]] if len(bones) > 1 else [])
        self._build_points()

    # -- model points -------------------------------------------------------------------------------
    def _build_points(self) -> None:
        from anny.keypoints import KeypointsRegressor

        coco = KeypointsRegressor.coco(self.model)
        rest = self.rest(torch.full((6,), 0.5))
        v0 = rest.rest_vertices
        self.point_names = model_point_names()
        vert_rows: list[torch.Tensor] = []  # one [V] weight row per surface point
        self._kind, self._slot = [], []
        for name in self.point_names:
            kind, _, what = name.partition(":")
            if kind == "coco":
                row = coco.regression_weights[coco.labels.index(what)]
                # The regressor spreads tiny weights over most of the mesh; dropping those below 1e-4
                # (< 0.6 % of the mass) leaves ~1k vertices to skin instead of ~8k.
                row = torch.where(row.abs() > 1e-4, row, torch.zeros_like(row))
                vert_rows.append(row / row.sum())
                self._kind.append(0)
                self._slot.append(len(vert_rows) - 1)
            elif kind == "tip":
                # The vertex most skinned to this bone that lies farthest along it: the fingertip.
                j = self.body.bone_index(what)
                w = (self.body.skin_weights * (self.body.skin_indices == j)).sum(1)
                head = rest.rest_heads[j]
                axis = rest.rest_poses[j, :3, 1]  # Anny bones point along their local +Y
                score = torch.where(w > 0.5, (v0 - head) @ axis, torch.full_like(w, -1e9))
                row = torch.zeros(v0.shape[0])
                row[int(score.argmax())] = 1
                vert_rows.append(row)
                self._kind.append(0)
                self._slot.append(len(vert_rows) - 1)
            elif kind == "head":
                self._kind.append(1)
                self._slot.append(self.body.bone_index(what))
            else:
                raise ValueError(f"unknown model point {name!r}")
        dense = torch.stack(vert_rows)                                   # [Kv, V]
        support = torch.nonzero(dense.abs().sum(0) > 0).squeeze(1)      # only these vertices are skinned
        self._support = support
        self._vert_weights = dense[:, support]                           # [Kv, S]
        self._kind_t = torch.tensor(self._kind)
        self._slot_t = torch.tensor(self._slot)

    def index(self, name: str) -> int:
        return self.point_names.index(name)

    # -- rest model and posing ----------------------------------------------------------------------
    def rest(self, phenotype: torch.Tensor) -> RestModel:
        """Rest model for phenotype [6] in [0, 1] (differentiable)."""
        m = self.model
        coeffs = m._get_phenotype_blendshape_coefficients(
            phenotype[None], torch.zeros(1, 0), torch.zeros(1, len(m.facial_action_labels))
        )
        r = m.get_rest_model(coeffs)
        return RestModel(r["rest_vertices"][0], r["rest_bone_heads"][0], r["rest_bone_poses"][0])

    def pose_matrices(self, rotvecs: torch.Tensor, transl: torch.Tensor) -> torch.Tensor:
        """Anny ``local-ref`` pose [T, J, 4, 4] from rotvecs [T, B, 3] (world-axis rotation vectors of
        ``fit_bones``; B may be shorter than ``fit_bones`` when hands are not fitted) and root
        translations [T, 3] (the posed root joint position, metres)."""
        t, b = rotvecs.shape[:2]
        pose = torch.eye(4).repeat(t, len(self.names), 1, 1)
        rot = roma.rotvec_to_rotmat(rotvecs)                              # [T, B, 3, 3]
        pose = _set_rotations(pose, self.fit_index[:b], rot)
        return _set_translation(pose, transl)

    def transforms(self, pose: torch.Tensor, rest: RestModel) -> torch.Tensor:
        """Rest→posed bone transforms [T, J, 4, 4] for pose [T, J, 4, 4]."""
        tr, _ = self.model.get_bone_transforms(pose, rest.rest_poses[None])
        return tr

    def points(self, transforms: torch.Tensor, rest: RestModel) -> torch.Tensor:
        """Posed model points [T, P, 3] (world, metres) in ``point_names`` order."""
        sup = linear_blend_skinning(
            rest.rest_vertices[self._support], self.body.skin_indices[self._support],
            self.body.skin_weights[self._support], transforms,
        )                                                                 # [T, S, 3]
        surf = torch.einsum("ks,tsd->tkd", self._vert_weights, sup)       # [T, Kv, 3]
        heads = rest.rest_heads[self._slot_t]                             # [P, 3] (used where kind == 1)
        tj = transforms[:, self._slot_t]                                  # [T, P, 4, 4]
        joint = (tj[..., :3, :3] @ heads[..., None])[..., 0] + tj[..., :3, 3]
        is_surf = (self._kind_t == 0)[None, :, None]
        surf_full = surf[:, self._slot_t.clamp(max=surf.shape[1] - 1)]
        return torch.where(is_surf, surf_full, joint)

    def vertices(self, transforms: torch.Tensor, rest: RestModel) -> torch.Tensor:
        """Posed mesh vertices [T, V, 3]."""
        return linear_blend_skinning(rest.rest_vertices, self.body.skin_indices, self.body.skin_weights,
                                     transforms)


def _set_rotations(pose: torch.Tensor, index: torch.Tensor, rot: torch.Tensor) -> torch.Tensor:
    """``pose`` with the 3×3 blocks of bones ``index`` replaced by ``rot`` (out of place, for autograd)."""
    mask = torch.zeros(pose.shape[1], 1, 1, dtype=torch.bool)
    mask[index] = True
    full = torch.zeros(pose.shape[0], pose.shape[1], 3, 3, dtype=rot.dtype)
    full = full.index_copy(1, index, rot)
    block = torch.where(mask, full, pose[..., :3, :3])
    top = torch.cat([block, pose[..., :3, 3:]], -1)
    return torch.cat([top, pose[..., 3:, :]], -2)


def _set_translation(pose: torch.Tensor, transl: torch.Tensor) -> torch.Tensor:
    """``pose`` with the root translation replaced by ``transl`` [T, 3] (out of place)."""
    root = torch.cat([pose[:, :1, :3, :3], transl[:, None, :, None]], -1)
    root = torch.cat([root, pose[:, :1, 3:]], -2)
    return torch.cat([root, pose[:, 1:]], 1)


def to_numpy(x: torch.Tensor) -> np.ndarray:
    return x.detach().cpu().numpy()
