"""The SMPL-X body through the ``smplx`` package, with model files the user supplies (their licence
forbids shipping them): ``--smplx-dir DIR`` or ``$GMA_SMPLX_DIR`` holding ``SMPLX_NEUTRAL.npz`` (or
``_MALE``/``_FEMALE``, ``.npz`` or ``.pkl``, directly or in a ``smplx/`` subfolder), from
https://smpl-x.is.tue.mpg.de.

SMPL-X is Y-up, faces +Z, metres, 10475 vertices, 55 joints. Parameters follow the sequence format's
``body.npz``: "shape" = betas [B], "expression" [E], "pose" [55, 3] axis-angles (global orient, 21 body
joints, jaw, left eye, right eye, 15 left-hand, 15 right-hand joints; hands as full axis-angles, not
PCA), "transl" [3].

SMPL-X's pose-corrective blendshapes depend on the pose, so here the *rest vertices* of a frame include
them (shape + expression + pose correctives, smplx's ``v_posed``) and the bone transforms are smplx's
``rel_transforms`` with the translation added: LBS of the two gives exactly smplx's vertices. The GPU
path then needs the rest vertices re-uploaded per frame (V × 12 bytes), or — for speed — the correctives
dropped (``pose_correctives=False``), which is what the viewer does.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import torch

from gma.body.base import BodyModel, BodyParams, ParamSpace
from gma.body.params import find_model_file
from gma.body.parts import REGIONS, regions_from_bones
from gma.body.skinning import dense_to_sparse_weights

__all__ = ["SMPLX_URL", "SmplxBody", "check_smplx_file"]

SMPLX_URL = "https://smpl-x.is.tue.mpg.de"
NUM_JOINTS = 55
_POSE_SPACE_DIM = (NUM_JOINTS - 1) * 9  # posedirs rows: (R - I) of every joint but the root

# Arrays the smplx SMPLX class reads, with their expected shapes (V vertices, F faces, S shape+expression
# dims, P = 486 pose-corrective dims, J = 55 joints); -1 = any size.
_REQUIRED = {
    "v_template": (-1, 3),
    "f": (-1, 3),
    "shapedirs": (-1, 3, -1),
    "posedirs": (-1, 3, _POSE_SPACE_DIM),
    "J_regressor": (NUM_JOINTS, -1),
    "weights": (-1, NUM_JOINTS),
    "kintree_table": (2, NUM_JOINTS),
    "hands_componentsl": (45, 45),
    "hands_componentsr": (45, 45),
    "hands_meanl": (45,),
    "hands_meanr": (45,),
    "lmk_faces_idx": (-1,),
    "lmk_bary_coords": (-1, 3),
}


def _hint() -> str:
    return (f"SMPL-X model files are not shipped with GMA: register at {SMPLX_URL}, download the "
            "SMPL-X model (SMPLX_NEUTRAL.npz etc.) and pass --smplx-dir DIR or set GMA_SMPLX_DIR=DIR.")


def check_smplx_file(path: Path) -> dict[str, tuple[int, ...]]:
    """Check an SMPL-X ``.npz`` without unpickling anything: every array SMPLX needs is present with
    the right shape. Returns the shapes; raises ValueError naming the file and the problem."""
    try:
        data = np.load(path, allow_pickle=False)
    except Exception as exc:
        raise ValueError(f"{path}: not a readable SMPL-X .npz file ({exc}). {_hint()}") from exc
    shapes: dict[str, tuple[int, ...]] = {}
    with data:
        for key, want in _REQUIRED.items():
            if key not in data.files:
                raise ValueError(f"{path}: not an SMPL-X model file, array {key!r} is missing. {_hint()}")
            try:
                got = tuple(data[key].shape)
            except ValueError as exc:  # an object array: would need pickle
                raise ValueError(f"{path}: array {key!r} is not a plain numeric array ({exc})") from exc
            if len(got) != len(want) or any(w not in (-1, g) for w, g in zip(want, got, strict=True)):
                raise ValueError(f"{path}: array {key!r} has shape {list(got)}, expected "
                                 f"{['*' if w == -1 else w for w in want]}")
            shapes[key] = got
    v = shapes["v_template"][0]
    for key, axis in (("shapedirs", 0), ("posedirs", 0), ("weights", 0), ("J_regressor", 1)):
        if shapes[key][axis] != v:
            raise ValueError(f"{path}: {key!r} has {shapes[key][axis]} vertices, v_template has {v}")
    return shapes


def _find_file(smplx_dir: str | os.PathLike | None, gender: str) -> Path:
    if smplx_dir is not None and Path(smplx_dir).is_file():
        return Path(smplx_dir)
    return find_model_file("smplx", gender, smplx_dir)


class SmplxBody(BodyModel):
    """SMPL-X as a :class:`BodyModel`. Create with :meth:`load`; ``smplx_model`` is the underlying
    ``smplx.SMPLX`` module (its buffers are what posing uses)."""

    @staticmethod
    def load(smplx_dir: str | os.PathLike | None = None, gender: str = "neutral", num_betas: int = 10,
             num_expression_coeffs: int = 10, flat_hand_mean: bool = False,
             pose_correctives: bool = True) -> SmplxBody:
        """Load the user's SMPL-X model for ``gender`` from ``smplx_dir`` (a folder or the file itself;
        default ``$GMA_SMPLX_DIR``). Raises FileNotFoundError / ValueError saying what file is expected
        and where to get it."""
        path = _find_file(smplx_dir, gender)
        if path.suffix == ".npz":
            check_smplx_file(path)
        try:
            import smplx
        except ImportError as exc:
            raise ImportError("the SMPL-X body needs the smplx package: pip install 'gma[smplx]'") from exc
        model = smplx.SMPLX(
            str(path), ext=path.suffix.lstrip("."), gender=gender, num_betas=num_betas,
            num_expression_coeffs=num_expression_coeffs, use_pca=False, flat_hand_mean=flat_hand_mean,
            batch_size=1,
        )
        model.requires_grad_(False)
        return SmplxBody(model, pose_correctives=pose_correctives, source=path)

    def __init__(self, model, pose_correctives: bool = True, source: Path | None = None):
        from smplx.joint_names import JOINT_NAMES

        self.smplx_model = model
        self.source = source
        self.pose_correctives = pose_correctives
        faces = torch.as_tensor(np.asarray(model.faces, np.int64))
        parents = model.parents.tolist()
        parents[0] = -1
        bone_names = tuple(JOINT_NAMES[:NUM_JOINTS])
        idx, w = dense_to_sparse_weights(model.lbs_weights.float())
        regions = regions_from_bones(faces, idx, w, bone_names)
        base = [r for r in REGIONS if r in ("head", "torso", "arms", "hands", "legs", "feet")]
        labels = torch.stack([regions[r] for r in base]).float().argmax(0)
        super().__init__(
            name="smplx", up_axis="y", faces=faces,
            # No UV layout in the model file: zeros (a UV map can be set from SMPL-X's uv .obj later).
            face_uvs=torch.zeros(faces.shape[0], 3, 2),
            skin_indices=idx, skin_weights=w, bone_names=bone_names, bone_parents=tuple(parents),
            face_label_names=tuple(base), face_labels=labels, regions=regions,
        )
        nb, ne = model.num_betas, model.num_expression_coeffs
        self._spaces = {
            "shape": ParamSpace("shape", tuple(f"beta{i}" for i in range(nb)), (), np.zeros(nb, np.float32),
                                np.full(nb, -3.0, np.float32), np.full(nb, 3.0, np.float32),
                                "SMPL-X betas (PCA shape, about ±3 standard deviations)"),
            "expression": ParamSpace("expression", tuple(f"expr{i}" for i in range(ne)), (),
                                     np.zeros(ne, np.float32), np.full(ne, -2.0, np.float32),
                                     np.full(ne, 2.0, np.float32), "SMPL-X expression PCA coefficients"),
            "pose": ParamSpace("pose", bone_names, (3,), np.zeros((NUM_JOINTS, 3), np.float32), None, None,
                               "axis-angle per joint (radians) relative to the parent; zeros = T-pose"),
            "transl": ParamSpace("transl", ("x", "y", "z"), (), np.zeros(3, np.float32), None, None,
                                 "global translation (m)"),
        }

    @property
    def param_spaces(self) -> dict[str, ParamSpace]:
        return self._spaces

    def canonical_pose(self) -> torch.Tensor:
        """A relaxed A-pose: shoulders lowered 40° so the arms clear the torso (SMPL-X is a T-pose)."""
        pose = self._spaces["pose"].default_tensor()
        pose[self.bone_names.index("left_shoulder"), 2] = -0.7
        pose[self.bone_names.index("right_shoulder"), 2] = 0.7
        return pose

    # -- posing -------------------------------------------------------------------------------------
    def _rotations(self, pose: torch.Tensor) -> tuple[torch.Tensor, tuple[int, ...]]:
        """[B, 55, 3, 3] joint rotations (the model's hand mean added, as smplx does) and the batch."""
        from smplx.lbs import batch_rodrigues

        lead = tuple(pose.shape[:-2])
        full = pose.reshape(-1, NUM_JOINTS * 3) + self.smplx_model.pose_mean.to(pose.dtype)
        return batch_rodrigues(full.reshape(-1, 3)).reshape(-1, NUM_JOINTS, 3, 3), lead

    def _shaped(self, params: BodyParams) -> torch.Tensor:
        from smplx.lbs import blend_shapes

        m = self.smplx_model
        betas = params["shape"].reshape(-1, m.num_betas)
        expr = params["expression"].reshape(-1, m.num_expression_coeffs)
        b = max(betas.shape[0], expr.shape[0])
        coeffs = torch.cat([betas.expand(b, -1), expr.expand(b, -1)], 1)
        return m.v_template + blend_shapes(coeffs, torch.cat([m.shapedirs, m.expr_dirs], -1))  # [B, V, 3]

    def rest_vertices(self, params: BodyParams) -> torch.Tensor:
        params = self.check_params(params)
        v = self._shaped(params)
        lead: tuple[int, ...] = ()
        if self.pose_correctives:
            rot, lead = self._rotations(params["pose"])
            feature = (rot[:, 1:] - torch.eye(3)).reshape(rot.shape[0], -1)
            v = v + (feature @ self.smplx_model.posedirs).reshape(rot.shape[0], -1, 3)
        lead = lead or tuple(params["shape"].shape[:-1]) or tuple(params["expression"].shape[:-1])
        return v.reshape(*lead, -1, 3) if lead else v[0]

    def bone_transforms(self, params: BodyParams) -> torch.Tensor:
        from smplx.lbs import batch_rigid_transform, vertices2joints

        params = self.check_params(params)
        rot, lead = self._rotations(params["pose"])
        joints = vertices2joints(self.smplx_model.J_regressor, self._shaped(params))
        joints = joints.expand(rot.shape[0], -1, -1)
        _, transforms = batch_rigid_transform(rot, joints, self.smplx_model.parents)
        transl = params["transl"].reshape(-1, 3)
        transforms = transforms.clone()
        transforms[..., :3, 3] = transforms[..., :3, 3] + transl[:, None, :]
        return transforms.reshape(*lead, NUM_JOINTS, 4, 4) if lead else transforms[0]
