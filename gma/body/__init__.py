"""Parametric bodies: the ``BodyModel`` interface, the Anny (default, free) and SMPL-X backends, mesh
geometry, skinning and surfel placement in torch, GPU posing in WGSL, and built-in motions.

Nothing here loads a model or touches a GPU at import; ``load_body("anny")`` creates (and caches) one.
The GPU side is ``gma.body.gpu_posing.GpuPoser`` (imported on demand: it needs wgpu).
"""

from gma.body.base import BodyModel, BodyParams, BodyPose, ParamSpace
from gma.body.motions import MOTIONS, Motion, load_anny_motion, motion
from gma.body.placement import SurfelBinding, place_surfels, uniform_surfels
from gma.body.registry import load_body
from gma.body.skinning import linear_blend_skinning

__all__ = [
    "MOTIONS",
    "BodyModel",
    "BodyParams",
    "BodyPose",
    "Motion",
    "ParamSpace",
    "SurfelBinding",
    "linear_blend_skinning",
    "load_anny_motion",
    "load_body",
    "motion",
    "place_surfels",
    "uniform_surfels",
]
