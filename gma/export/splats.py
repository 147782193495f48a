"""Posed surfels of an avatar as a standard Gaussian-splat PLY.

The surfels are posed in torch with the same morph, skinning and placement as the GPU path
(``gma.avatar.posing.pose_surfels`` is the reference for ``GpuPoser``), so a splat renderer that reads
the file draws the avatar as GMA does.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from gma.avatar.avatar import Avatar
from gma.avatar.model import DecodedAvatar
from gma.avatar.posing import pose_surfels
from gma.render.ply import save_splat_ply

__all__ = ["SPLAT_FORMATS", "posed_splats", "write_splats"]

SPLAT_FORMATS = ("3dgs", "2dgs")
# Flat-axis size given to a surfel in the 3DGS layout (m): thin enough that the disc renders like the
# surfel, thick enough that 3DGS viewers (which invert the covariance) stay well conditioned.
DEFAULT_THICKNESS = 1e-4


@torch.no_grad()
def posed_splats(avatar: Avatar, body, params: dict, decoded: DecodedAvatar | None = None) -> dict[str, np.ndarray]:
    """The avatar's surfels posed for body ``params`` (shape defaults to the avatar's identity).

    Returns float32 arrays means [N, 3] (m, body world frame), quats [N, 4] (w, x, y, z), scales [N, 2]
    (m), opacities [N], colors [N, 3] in [0, 1]; and ``vertices`` [V, 3] the posed morphed mesh.
    """
    decoded = decoded or avatar.decode()
    params = body.check_params({"shape": avatar.shape, **params})
    posed = pose_surfels(decoded, body.faces, body.skin_indices, body.skin_weights, body.rest_vertices(params),
                         body.bone_transforms(params))
    keys = ("means", "quats", "scales", "opacities", "colors", "vertices")
    return {k: np.ascontiguousarray(posed[k].detach().cpu().numpy(), np.float32) for k in keys}


def write_splats(path: str | Path, splats: dict[str, np.ndarray], layout: str = "3dgs", sh_degree: int = 0,
                 thickness: float = DEFAULT_THICKNESS) -> Path:
    """Write ``splats`` (from :func:`posed_splats`) as a PLY: ``layout`` "3dgs" (three log scales, the
    normal axis ``thickness`` metres) or "2dgs" (two scales); ``sh_degree`` 0 or 3 (rest coefficients 0)."""
    if layout not in SPLAT_FORMATS:
        raise ValueError(f"splat layout must be one of {SPLAT_FORMATS}, got {layout!r}")
    save_splat_ply(path, splats["means"], splats["quats"], splats["scales"], splats["opacities"], splats["colors"],
                   thickness=thickness if layout == "3dgs" else None, sh_degree=sh_degree)
    return Path(path)
