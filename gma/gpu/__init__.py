"""GPU layer: adapter and device choice, WGSL loading, pipeline cache, transfers, GPU timestamps.

Nothing here touches a GPU at import time; a :class:`GpuContext` is created on demand and passed
explicitly to the code that needs it (``get_context()`` returns a lazily created shared one).
"""

from gma.gpu.context import GpuContext, NoAdapterError, get_context
from gma.gpu.shaders import ShaderCompileError, ShaderLibrary
from gma.gpu.timing import PassTimer
from gma.gpu.transfers import TransferStats

__all__ = [
    "GpuContext",
    "NoAdapterError",
    "PassTimer",
    "ShaderCompileError",
    "ShaderLibrary",
    "TransferStats",
    "get_context",
]
