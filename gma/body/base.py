"""The ``BodyModel`` interface every parametric body (Anny, SMPL-X) implements.

A body is a triangle mesh whose canonical ("rest") vertices depend on shape and expression parameters and
whose posed vertices come from linear-blend skinning (LBS) of the rest vertices by per-frame bone
transforms:

    posed_v = Σ_k skin_weights[v, k] · bone_transforms[skin_indices[v, k]] · [rest_v, 1]

Splitting posing into (rest vertices, bone transforms) is what lets the GPU skin: the avatar adds its
per-vertex morph offsets to the rest vertices once (torch), uploads them, and every frame only the
[J, 4, 4] bone transforms travel to the GPU (``gma.body.gpu_posing``).

Units are metres. Each backend keeps its native axes (``up_axis``: Anny is Z-up and faces −Y, SMPL-X is
Y-up and faces +Z); cameras in a sequence are expressed in the same world frame.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass, field

import numpy as np
import torch

from gma.body.skinning import linear_blend_skinning

__all__ = ["BodyModel", "BodyParams", "BodyPose", "ParamSpace"]

# A set of body parameters, keyed by parameter space name ("shape", "pose", "expression", and for
# SMPL-X "transl"); values are tensors whose per-space layout is given by ``BodyModel.param_spaces``.
BodyParams = dict[str, torch.Tensor]


@dataclass(frozen=True)
class ParamSpace:
    """One named parameter space of a body model (what a UI slider panel or an optimiser sees).

    ``labels`` name the entries; each entry is a block of ``entry_shape`` numbers (``()`` for a scalar,
    ``(4, 4)`` for an Anny bone delta transform, ``(3,)`` for an SMPL-X axis-angle). ``low``/``high``
    are per-entry ranges for scalar spaces (None where a range makes no sense, e.g. rotations), and
    ``default`` the neutral value, shaped ``[len(labels), *entry_shape]``.
    """

    name: str
    labels: tuple[str, ...]
    entry_shape: tuple[int, ...]
    default: np.ndarray
    low: np.ndarray | None = None
    high: np.ndarray | None = None
    doc: str = ""

    @property
    def size(self) -> int:
        return len(self.labels)

    def default_tensor(self, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        return torch.as_tensor(self.default, dtype=dtype).clone()

    def validate(self, value: torch.Tensor) -> None:
        """Raise ValueError unless ``value`` is ``[..., size, *entry_shape]``."""
        want = (self.size, *self.entry_shape)
        if tuple(value.shape[value.dim() - len(want):]) != want:
            raise ValueError(
                f"body parameter {self.name!r} must have shape [..., {', '.join(map(str, want))}], "
                f"got {tuple(value.shape)}"
            )

    def check_values(self, value: torch.Tensor) -> None:
        """Raise ValueError unless ``value`` has the right shape (:meth:`validate`), is finite and, where
        the space declares a range, lies in ``[low, high]``; the message names the first bad entry and its
        range. For values a user sets (an edit, the viewer's sliders); posing only checks shapes, since
        an optimiser may step outside the range on its way."""
        value = torch.as_tensor(value, dtype=torch.float32)
        self.validate(value)
        flat = value.reshape(-1, self.size, *self.entry_shape).numpy()
        ranged = self.low is not None and self.high is not None and not self.entry_shape
        bad = ~np.isfinite(flat)
        if ranged:
            bad |= (flat < self.low) | (flat > self.high)
        if bad.any():
            at = tuple(np.argwhere(bad)[0])
            label = self.labels[at[1]]
            where = f"a finite number in [{self.low[at[1]]:g}, {self.high[at[1]]:g}]" if ranged else "a finite number"
            raise ValueError(f"{self.name} entry {label!r} is {flat[at]:g}, not {where}")


@dataclass
class BodyPose:
    """A posed body. Leading batch dimensions ``...`` follow the pose parameters.

    rest_vertices:   [..., V, 3] canonical vertices (shape + expression, and SMPL-X pose correctives)
    bone_transforms: [..., J, 4, 4] rest→posed rigid transforms, the LBS input
    vertices:        [..., V, 3] posed vertices = LBS(rest_vertices, bone_transforms)
    """

    rest_vertices: torch.Tensor
    bone_transforms: torch.Tensor
    vertices: torch.Tensor


@dataclass(eq=False, repr=False)  # holds large tensors: identity equality, short repr
class BodyModel(ABC):
    """Mesh, rig and parameter spaces of a parametric body.

    Fields (torch tensors on the CPU, float32 / int64):
        faces:         [F, 3] vertex indices, counter-clockwise seen from outside
        face_uvs:      [F, 3, 2] texture coordinates per face corner (in [0, 1]; seams allowed)
        skin_indices:  [V, K] bone index per vertex influence
        skin_weights:  [V, K] LBS weights (each row sums to 1; unused slots have weight 0)
        bone_names:    J names; ``bone_parents`` J parent indices (root: -1)
        face_labels:   [F] index into ``face_label_names`` (fine parts from the backend's segmentation)
        regions:       coarse garment-selection regions, name -> [F] bool mask (may overlap)
    """

    name: str
    up_axis: str
    faces: torch.Tensor
    face_uvs: torch.Tensor
    skin_indices: torch.Tensor
    skin_weights: torch.Tensor
    bone_names: tuple[str, ...]
    bone_parents: tuple[int, ...]
    face_label_names: tuple[str, ...]
    face_labels: torch.Tensor
    regions: dict[str, torch.Tensor] = field(default_factory=dict)

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({self.name!r}, V={self.num_vertices}, F={self.num_faces}, "
                f"J={self.num_bones}, up={self.up_axis!r})")

    # -- sizes -------------------------------------------------------------------------------------
    @property
    def num_vertices(self) -> int:
        return int(self.skin_indices.shape[0])

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def num_bones(self) -> int:
        return len(self.bone_names)

    # -- parameters --------------------------------------------------------------------------------
    @property
    @abstractmethod
    def param_spaces(self) -> dict[str, ParamSpace]:
        """The named parameter spaces (at least "shape", "pose" and "expression")."""

    def default_params(self) -> BodyParams:
        """Neutral parameters (average shape, the backend's rest pose, neutral expression)."""
        return {k: s.default_tensor() for k, s in self.param_spaces.items()}

    def canonical_params(self, shape: torch.Tensor | None = None) -> BodyParams:
        """Parameters of the canonical pose used for editing (A-pose for Anny, a relaxed A-pose for
        SMPL-X) with the given shape and a neutral expression."""
        params = self.default_params()
        if shape is not None:
            params["shape"] = shape
        params["pose"] = self.canonical_pose()
        return params

    @abstractmethod
    def canonical_pose(self) -> torch.Tensor:
        """The "pose" parameter value of the editing pose."""

    def check_params(self, params: BodyParams) -> BodyParams:
        """``params`` completed with defaults for missing spaces; raises ValueError on unknown names or
        wrong shapes, naming the parameter."""
        spaces = self.param_spaces
        unknown = set(params) - set(spaces)
        if unknown:
            raise ValueError(f"unknown body parameters {sorted(unknown)}; {self.name} has {sorted(spaces)}")
        out = self.default_params()
        for key, value in params.items():
            value = torch.as_tensor(value, dtype=torch.float32)
            spaces[key].validate(value)
            out[key] = value
        return out

    # -- posing ------------------------------------------------------------------------------------
    @abstractmethod
    def rest_vertices(self, params: BodyParams) -> torch.Tensor:
        """[..., V, 3] canonical vertices for the parameters' shape and expression (pose ignored,
        except SMPL-X pose correctives when the backend uses them)."""

    @abstractmethod
    def bone_transforms(self, params: BodyParams) -> torch.Tensor:
        """[..., J, 4, 4] rest→posed bone transforms for the parameters' pose (and shape, which moves
        the joints)."""

    def pose(self, params: BodyParams) -> BodyPose:
        """Rest vertices, bone transforms and posed vertices, differentiable w.r.t. the parameters."""
        params = self.check_params(params)
        rest = self.rest_vertices(params)
        transforms = self.bone_transforms(params)
        posed = linear_blend_skinning(rest, self.skin_indices, self.skin_weights, transforms)
        return BodyPose(rest_vertices=rest, bone_transforms=transforms, vertices=posed)

    def region_mask(self, region: str) -> torch.Tensor:
        """[F] bool mask of a coarse region or a fine face label."""
        if region in self.regions:
            return self.regions[region]
        if region in self.face_label_names:
            return self.face_labels == self.face_label_names.index(region)
        known = sorted(self.regions) + list(self.face_label_names)
        raise ValueError(f"unknown body region {region!r}; known: {known}")
