"""GMA: Gaussian Morphing Avatars rendered with WGSL compute shaders through wgpu."""

__version__ = "0.1.0"
