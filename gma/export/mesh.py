"""The avatar's mesh layer (the morphed body mesh) posed, coloured from its surfels, through trimesh
(GLB, OBJ, PLY).

Colours: a face takes the opacity-weighted mean colour of the surfels bound to it, and a vertex the
mean of its faces. With a texture size, the body's UVs are kept (vertices split at UV seams) and the
colours are baked into a texture instead (each texel interpolates its face's vertex colours).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import trimesh
from PIL import Image

from gma.avatar.model import DecodedAvatar
from gma.core.atomic import atomic_write_bytes
from gma.core.checks import require_finite
from gma.core.errors import NonFiniteError
from gma.synth.uv_bake import dilate, rasterize_uv

__all__ = ["MESH_SUFFIXES", "posed_mesh", "surfel_vertex_colors", "write_mesh"]

MESH_SUFFIXES = (".glb", ".obj", ".ply")


def surfel_vertex_colors(decoded: DecodedAvatar, faces: np.ndarray, num_vertices: int) -> np.ndarray:
    """[V, 3] colours in [0, 1]: per face the opacity-weighted mean of its surfels' colours, per vertex
    the mean over its faces (faces without surfels count as grey)."""
    f = len(faces)
    face_id = decoded.binding.face_id.numpy()
    w = decoded.opacities.numpy().astype(np.float64) + 1e-6
    col = decoded.colors.numpy().astype(np.float64)
    wsum = np.bincount(face_id, w, minlength=f)
    face_rgb = np.stack([np.bincount(face_id, w * col[:, c], minlength=f) for c in range(3)], 1)
    face_rgb = np.where(wsum[:, None] > 0, face_rgb / np.maximum(wsum, 1e-12)[:, None], 0.5)
    vsum = np.zeros((num_vertices, 3))
    count = np.bincount(faces.ravel(), minlength=num_vertices).astype(np.float64)
    for k in range(3):
        np.add.at(vsum, faces[:, k], face_rgb)
    return (vsum / np.maximum(count, 1)[:, None]).clip(0, 1)


def posed_mesh(vertices: np.ndarray, faces: np.ndarray, colors: np.ndarray, face_uvs: np.ndarray | None = None,
               texture_size: int = 0) -> trimesh.Trimesh:
    """A trimesh of the posed mesh ``vertices`` [V, 3] (m), ``faces`` [F, 3], per-vertex ``colors`` [V, 3].
    ``texture_size`` > 0 with ``face_uvs`` [F, 3, 2]: UV-mapped, colours baked into an S×S texture."""
    if texture_size <= 0 or face_uvs is None:
        rgba = np.concatenate([colors, np.ones((len(colors), 1))], 1)
        return trimesh.Trimesh(vertices, faces, vertex_colors=(rgba * 255).round().astype(np.uint8), process=False)
    # One output vertex per distinct (vertex, uv) corner: the UV seams split the mesh there.
    corner_uv = face_uvs.reshape(-1, 2).astype(np.float64)
    key = np.concatenate([faces.reshape(-1, 1).astype(np.float64), np.round(corner_uv * 1e6)], 1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    src_vertex = faces.reshape(-1)[first]
    new_faces = inverse.reshape(-1, 3)
    face_id, bary = rasterize_uv(face_uvs, texture_size)
    covered = face_id >= 0
    tex = np.zeros((texture_size, texture_size, 3))
    corners = colors[faces[face_id[covered]]]  # [K, 3, 3] vertex colours of each texel's face
    tex[covered] = np.einsum("kc,kcj->kj", bary[covered], corners)
    tex = dilate(tex, covered)
    image = Image.fromarray((tex.clip(0, 1) * 255).round().astype(np.uint8))
    material = trimesh.visual.material.SimpleMaterial(image=image)
    visual = trimesh.visual.TextureVisuals(uv=corner_uv[first], image=image, material=material)
    return trimesh.Trimesh(vertices[src_vertex], new_faces, visual=visual, process=False)


def write_mesh(path: str | Path, mesh: trimesh.Trimesh) -> Path:
    """Write ``mesh`` in the format of ``path``'s suffix (.glb, .obj, .ply). An OBJ with a texture also
    writes its material and image next to it (``NAME.mtl``, ``NAME.png``)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in MESH_SUFFIXES:
        raise ValueError(f"{path}: mesh formats are {', '.join(MESH_SUFFIXES)}")
    require_finite({"the mesh vertices": mesh.vertices}, f"{path}: not written", NonFiniteError)
    if suffix == ".obj":
        files = trimesh.exchange.obj.export_obj(mesh, include_texture=True, return_texture=True,
                                                mtl_name=f"{path.stem}.mtl", write_texture=False)
        text, extra = (files, {}) if isinstance(files, str) else files
        for name, data in extra.items():
            atomic_write_bytes(path.parent / name, data)
        atomic_write_bytes(path, text.encode())
    else:
        atomic_write_bytes(path, mesh.export(file_type=suffix[1:]))
    return path
