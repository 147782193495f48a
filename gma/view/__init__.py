"""The viewer's library part, free of any window: surfel sources, the orbit camera, the frame renderer
(drawing into any texture view, offscreen included), face selection, recording and frame statistics.

Nothing touches a GPU at import; every drawing object takes a :class:`gma.gpu.GpuContext`.
"""

from gma.view.orbit import CameraPath, OrbitCamera
from gma.view.renderer import DrawOptions, FrameRenderer, Scene, ScreenImage, read_texture
from gma.view.source import BodySource, MeshLayer, StaticSource, SurfelSource, load_source

__all__ = [
    "BodySource",
    "CameraPath",
    "DrawOptions",
    "FrameRenderer",
    "MeshLayer",
    "OrbitCamera",
    "Scene",
    "ScreenImage",
    "StaticSource",
    "SurfelSource",
    "load_source",
    "read_texture",
]
