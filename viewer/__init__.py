"""The GMA real-time viewer (glfw window + wgpu surface)."""
