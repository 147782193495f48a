"""The Anny body (default, free licence; PyPI ``anny``): the default 27k-face topology with eyes and
tongue, the 104-bone rig with hands, 6 phenotype parameters and the 52 ARKit-style facial actions.

Anny is Z-up, faces −Y, metres. Pose parameters are Anny's ``local-ref`` delta transforms
[J, 4, 4]: per bone a rigid transform relative to its rest orientation, expressed in world-aligned axes
(bone 0 is the root and carries the global rotation and translation). Identity everywhere is Anny's rest
pose — an A-pose with the root at the origin — which is also the canonical pose for editing.

Creating the model is slow the first time: anny builds a large cache (``AnnyBody.create``'s
``cache_dir``; by default ``$ANNY_CACHE_DIR``, else ``~/.cache/gma/anny``); later creations read that
cache, and within one process ``AnnyBody.create()`` returns the same object. Per frame, only forward
kinematics runs (rest vertices and rest bone poses are cached for the last shape/expression).
"""

from __future__ import annotations

import functools
import os
from pathlib import Path

import numpy as np
import torch

from gma.body.base import BodyModel, BodyParams, ParamSpace
from gma.body.parts import regions_from_bones

__all__ = ["AnnyBody"]


def _anny_face_labels(model, faces: torch.Tensor) -> tuple[tuple[str, ...], torch.Tensor]:
    """Fine labels from Anny's UV-space segmentation image: each face takes the colour under its UV
    centroid (the same lookup as ``anny.face_segmentation``, for all labels at once)."""
    import PIL.Image
    import yaml
    from anny.paths import get_anny_root_dir

    root = get_anny_root_dir() / "data" / "segmentation"
    image = np.asarray(PIL.Image.open(root / "body_parts_segmentation.png").convert("RGB"))
    with open(root / "body_parts_segmentation.yaml") as f:
        colors = yaml.safe_load(f)["colors"]
    uv = model.texture_coordinates[model.face_texture_coordinate_indices].mean(1).numpy()
    h, w = image.shape[:2]
    px = np.clip(np.round(uv[:, 0] * w).astype(np.int64), 0, w - 1)
    py = np.clip(np.round((1 - uv[:, 1]) * h).astype(np.int64), 0, h - 1)
    face_rgb = image[py, px]
    names = tuple(colors)
    labels = np.zeros(len(face_rgb), np.int64)  # colours matching no label (anti-aliasing) stay "body"
    for i, name in enumerate(names):
        labels[np.all(face_rgb == np.asarray(colors[name]), axis=1)] = i
    return names, torch.from_numpy(labels)


# One cache location whichever way GMA starts (make, a bare ``gma``, the tests), unless the user sets one.
DEFAULT_ANNY_CACHE_DIR = Path.home() / ".cache" / "gma" / "anny"


def anny_cache_dir(cache_dir: str | Path | None = None) -> Path:
    """Where anny keeps its cache: ``cache_dir``, else anny's own ``$ANNY_CACHE_DIR``, else GMA's default."""
    return Path(cache_dir or os.environ.get("ANNY_CACHE_DIR") or DEFAULT_ANNY_CACHE_DIR)


def _quiet_warp() -> None:
    """Quieten NVIDIA Warp, which anny imports and which prints a CUDA banner GMA has no use for."""
    try:
        import warp
    except ImportError:  # anny without its optional Warp skinning
        return
    warp.config.quiet = True


@functools.lru_cache(maxsize=4)
def _create(rig: str, topology: str, cache_dir: Path) -> AnnyBody:
    _quiet_warp()
    import anny
    from anny.paths import set_anny_cache_path

    # anny reads its cache folder when it builds or loads the model, through its own setting (which its
    # import took from $ANNY_CACHE_DIR): GMA passes its choice there rather than through the environment.
    set_anny_cache_path(cache_dir)

    model = anny.Anny(
        rig=rig,
        topology=topology,
        facial_actions="all",
        phenotypes="default",
        pose_parameterization="local-ref",
        skinning_method="lbs",  # the plain-torch path (warp is optional and CUDA-oriented)
    ).to(torch.float32)
    model.requires_grad_(False)
    return AnnyBody(model)


class AnnyBody(BodyModel):
    """Anny as a :class:`BodyModel`. Create with :meth:`create` (cached); ``anny_model`` is the
    underlying ``anny.Anny`` module (float32) for anything this wrapper does not expose."""

    @staticmethod
    def create(rig: str = "anny", topology: str = "anny", cache_dir: str | Path | None = None) -> AnnyBody:
        """The default Anny body (one instance per (rig, topology, cache folder) per process); anny's
        cache in ``cache_dir`` (default: :func:`anny_cache_dir`)."""
        return _create(rig, topology, anny_cache_dir(cache_dir))

    def __init__(self, model):
        self.anny_model = model
        faces = model.faces.long()
        face_uvs = model.texture_coordinates[model.face_texture_coordinate_indices].float()
        label_names, labels = _anny_face_labels(model, faces)
        bone_names = tuple(model.bone_labels)

        def label_mask(*names: str) -> torch.Tensor:
            idx = [label_names.index(n) for n in names if n in label_names]
            return torch.isin(labels, torch.tensor(idx, dtype=torch.long))

        head_labels = [n for n in label_names if n == "head" or n.startswith(("eye", "mouth", "tongue"))]
        regions = regions_from_bones(
            faces, model.vertex_bone_indices, model.vertex_bone_weights, bone_names,
            overrides={"head": label_mask(*head_labels), "hands": label_mask("hand.L", "hand.R"),
                       "feet": label_mask("foot.L", "foot.R")},
        )
        super().__init__(
            name="anny",
            up_axis="z",
            faces=faces,
            face_uvs=face_uvs,
            skin_indices=model.vertex_bone_indices.long(),
            skin_weights=model.vertex_bone_weights.float(),
            bone_names=bone_names,
            bone_parents=tuple(int(p) for p in model.bone_parents),
            face_label_names=label_names,
            face_labels=labels,
            regions=regions,
        )
        j, nph = len(bone_names), len(model.phenotype_labels)
        self._spaces = {
            "shape": ParamSpace(
                "shape", tuple(model.phenotype_labels), (), np.full(nph, 0.5, np.float32),
                np.zeros(nph, np.float32), np.ones(nph, np.float32),
                "Anny phenotype (gender, age, muscle, weight, height, proportions), each in [0, 1]",
            ),
            "pose": ParamSpace(
                "pose", bone_names, (4, 4), np.tile(np.eye(4, dtype=np.float32), (j, 1, 1)), None, None,
                "local-ref delta transform per bone; identity = rest A-pose, root at the origin",
            ),
            "expression": ParamSpace(
                "expression", tuple(model.facial_action_labels), (),
                np.zeros(len(model.facial_action_labels), np.float32),
                np.zeros(len(model.facial_action_labels), np.float32),
                np.ones(len(model.facial_action_labels), np.float32),
                "ARKit-style facial action weights in [0, 1]",
            ),
        }
        self._rest_cache: tuple[bytes, dict] | None = None

    @property
    def param_spaces(self) -> dict[str, ParamSpace]:
        return self._spaces

    def canonical_pose(self) -> torch.Tensor:
        return self._spaces["pose"].default_tensor()

    def bone_index(self, name: str) -> int:
        try:
            return self.bone_names.index(name)
        except ValueError:
            raise ValueError(f"Anny has no bone {name!r}") from None

    def expression_basis(self) -> torch.Tensor:
        """[52, V, 3] per-facial-action vertex offsets (m): rest vertices are linear in the expression,
        rest(shape, e) = rest(shape, 0) + Σ_k e_k · basis[k], and facial actions move no bone — so a
        viewer can blend expressions on the GPU without re-running the rest model."""
        m = self.anny_model
        rows = [i for i, label in enumerate(m.blendshape_labels) if label.startswith("facial_action:")]
        return m.blendshapes[rows].float()

    # -- posing -------------------------------------------------------------------------------------
    def _rest_model(self, shape: torch.Tensor, expression: torch.Tensor) -> dict:
        """Anny's rest model (rest vertices, rest bone poses) for [B, 6] shape and [B, 52] expression,
        cached for the last constant (no-grad) input so that per-frame posing skips the blendshapes."""
        m = self.anny_model
        cacheable = not (shape.requires_grad or expression.requires_grad)
        key = shape.numpy().tobytes() + b"|" + expression.numpy().tobytes() if cacheable else None
        if key is not None and self._rest_cache is not None and self._rest_cache[0] == key:
            return self._rest_cache[1]
        b = max(shape.shape[0], expression.shape[0])
        coeffs = m._get_phenotype_blendshape_coefficients(
            shape.expand(b, -1), torch.zeros(b, 0), expression.expand(b, -1)
        )
        rest = m.get_rest_model(coeffs)
        if key is not None:
            self._rest_cache = (key, rest)
        return rest

    @staticmethod
    def _flat(x: torch.Tensor, entry_dims: int) -> tuple[torch.Tensor, tuple[int, ...]]:
        lead = tuple(x.shape[: x.dim() - entry_dims - 1])
        return x.reshape(-1, *x.shape[x.dim() - entry_dims - 1:]), lead

    def rest_vertices(self, params: BodyParams) -> torch.Tensor:
        params = self.check_params(params)
        shape, lead = self._flat(params["shape"], 0)
        expr, lead_e = self._flat(params["expression"], 0)
        v = self._rest_model(shape, expr)["rest_vertices"]
        lead = lead if len(lead) >= len(lead_e) else lead_e
        return v.reshape(*lead, -1, 3) if lead else v[0]

    def bone_transforms(self, params: BodyParams) -> torch.Tensor:
        params = self.check_params(params)
        shape, _ = self._flat(params["shape"], 0)
        expr, _ = self._flat(params["expression"], 0)
        pose, lead = self._flat(params["pose"], 2)
        rest_poses = self._rest_model(shape, expr)["rest_bone_poses"]
        transforms, _ = self.anny_model.get_bone_transforms(pose, rest_poses)
        return transforms.reshape(*lead, *transforms.shape[1:]) if lead else transforms[0]
