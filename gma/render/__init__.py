"""The 2D Gaussian surfel renderer: WGSL passes through wgpu, a torch API and a torch reference."""

from gma.core.camera import Camera
from gma.render.api import RenderOutput, rasterize
from gma.render.options import RasterOptions
from gma.render.rasterizer import ForwardState, SurfelRasterizer, read_outputs
from gma.render.reference import rasterize_reference
from gma.render.surfels import SurfelBuffers

__all__ = [
    "Camera",
    "ForwardState",
    "RasterOptions",
    "RenderOutput",
    "SurfelBuffers",
    "SurfelRasterizer",
    "rasterize",
    "rasterize_reference",
    "read_outputs",
]
