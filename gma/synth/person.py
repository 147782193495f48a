"""The synthetic person: an Anny body of a seeded phenotype, dressed (garment labels and offsets) and
textured, ready to be posed frame by frame.

Uses ``gma.body``'s public API (``load_body``, ``BodyModel.rest_vertices`` / ``bone_transforms``,
``linear_blend_skinning``). Rest joint positions, which that API does not expose, come from the
underlying ``anny`` model's own forward pass (``AnnyBody.anny_model``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.body import linear_blend_skinning, load_body
from gma.synth.garments import Garments, dress
from gma.synth.mesh_raster import TexturedMesh, vertex_normals
from gma.synth.texture import Look, bake_texture

__all__ = ["SynthPerson", "make_person"]

_JOINTS = (
    "upperarm01.L",
    "upperarm01.R",
    "wrist.L",
    "wrist.R",
    "upperleg01.L",
    "upperleg01.R",
    "foot.L",
    "foot.R",
    "neck01",
    "head",
)


@dataclass
class SynthPerson:
    """phenotype [6]; rest [V, 3] clothed rest-pose vertices (body + offsets along rest normals);
    offsets [V, 3]; mesh (faces, face_uvs, texture); garments (labels, landmarks)."""

    body: object
    phenotype: np.ndarray
    body_rest: np.ndarray
    rest: np.ndarray
    offsets: np.ndarray
    mesh: TexturedMesh
    garments: Garments
    look: Look

    def posed_vertices(self, pose: np.ndarray, facial_actions: np.ndarray | None = None) -> np.ndarray:
        """Clothed vertices [T, V, 3] for Anny ``local-ref`` poses [T, 104, 4, 4] and optional facial
        actions [T, 52] (garment offsets ride on the expression-dependent rest shape)."""
        body = self.body
        shape = torch.as_tensor(self.phenotype, dtype=torch.float32)
        pose_t = torch.as_tensor(np.asarray(pose, np.float32))
        with torch.no_grad():
            transforms = body.bone_transforms({"shape": shape, "pose": pose_t})  # [T, J, 4, 4]
            rest = torch.as_tensor(self.rest, dtype=torch.float32).expand(transforms.shape[0], -1, -1)
            if facial_actions is not None and np.any(facial_actions):
                fa = torch.as_tensor(np.asarray(facial_actions, np.float32))
                moved = body.rest_vertices({"shape": shape.expand(len(fa), -1), "expression": fa})
                rest = rest + (moved - torch.as_tensor(self.body_rest))
            v = linear_blend_skinning(rest, body.skin_indices, body.skin_weights, transforms)
        return v.numpy().astype(np.float32)


def _rest_joints(body, phenotype: np.ndarray) -> dict[str, np.ndarray]:
    m = body.anny_model
    pose = torch.eye(4).expand(1, len(body.bone_names), 4, 4).clone()
    kw = {k: torch.tensor([float(v)]) for k, v in zip(m.phenotype_labels, phenotype, strict=True)}
    with torch.no_grad():
        heads = m(pose_parameters=pose, phenotype_kwargs=kw)["rest_bone_heads"][0].double().numpy()
    return {name: heads[body.bone_names.index(name)] for name in _JOINTS}


def make_person(seed: int, texture_size: int = 2048, body=None) -> SynthPerson:
    """The person for ``seed``: phenotype, clothes and texture all follow from it deterministically."""
    body = body or load_body("anny")
    rng = np.random.default_rng([seed, 1])  # a stream of its own, independent of motion/camera choices
    # gender, age, muscle, weight, height, proportions: adults of ordinary build.
    phenotype = np.array(
        [
            rng.uniform(0, 1),
            rng.uniform(0.45, 0.75),
            rng.uniform(0.3, 0.7),
            rng.uniform(0.3, 0.65),
            rng.uniform(0.35, 0.75),
            rng.uniform(0.35, 0.65),
        ],
        np.float32,
    )
    look = Look.from_seed(rng)
    with torch.no_grad():
        body_rest = body.rest_vertices({"shape": torch.as_tensor(phenotype)}).double().numpy()
    faces = body.faces.numpy()
    normals = vertex_normals(body_rest, faces)
    dense = np.zeros((len(body_rest), body.num_bones))
    np.put_along_axis(dense, body.skin_indices.numpy(), 0, axis=1)
    np.add.at(
        dense, (np.arange(len(body_rest))[:, None], body.skin_indices.numpy()), body.skin_weights.numpy()
    )
    garments = dress(
        body_rest,
        faces,
        dense.argmax(1),
        body.bone_names,
        _rest_joints(body, phenotype),
        sleeve_end=float(rng.uniform(0.82, 0.92)),
        flare=float(rng.uniform(0.7, 1.2)),
    )
    offsets = normals * garments.offsets[:, None]
    rest = body_rest + offsets
    face_uvs = body.face_uvs.numpy()
    texture = bake_texture(
        look,
        body_rest,
        normals,
        faces,
        face_uvs,
        garments,
        body.face_labels.numpy(),
        body.face_label_names,
        texture_size,
    )
    return SynthPerson(
        body,
        phenotype,
        body_rest.astype(np.float32),
        rest.astype(np.float32),
        offsets.astype(np.float32),
        TexturedMesh(faces, face_uvs, texture),
        garments,
        look,
    )
