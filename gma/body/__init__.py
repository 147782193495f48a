"""Parametric bodies: the ``BodyModel`` interface, the Anny (default, free) and SMPL-X backends, mesh
geometry, skinning and surfel placement in torch, GPU posing in WGSL, and built-in motions.

Nothing here loads a model or touches a GPU at import; ``load_body("anny")`` creates (and caches) one.
"""

from gma.body.base import BodyModel, BodyParams, BodyPose, ParamSpace
from gma.body.placement import SurfelBinding, place_surfels, uniform_surfels
from gma.body.registry import load_body
from gma.body.skinning import linear_blend_skinning

__all__ = [
    "BodyModel",
    "BodyParams",
    "BodyPose",
    "ParamSpace",
    "SurfelBinding",
    "linear_blend_skinning",
    "load_body",
    "place_surfels",
    "uniform_surfels",
]
