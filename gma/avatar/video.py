"""Turntable and animation videos of an avatar through the GPU posing path (``AvatarRenderer``)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from gma.data.cameras import look_at
from gma.render import Camera
from gma.render.image_io import to_uint8

__all__ = ["orbit_cameras", "render_turntable", "sequence_camera", "write_video"]


def orbit_cameras(w2c: np.ndarray, K: np.ndarray, width: int, height: int, frames: int, up=(0.0, 0.0, 1.0),
                  target=(0.0, 0.0, -0.05)) -> list[Camera]:
    """``frames`` cameras on a full circle about the vertical axis through ``target``, starting at the
    camera ``w2c`` [4, 4] with intrinsics ``K`` [3, 3] (already for width × height)."""
    r, t = w2c[:3, :3], w2c[:3, 3]
    eye0 = -r.T @ t
    up = np.asarray(up, np.float64)
    target = np.asarray(target, np.float64)
    out = []
    for i in range(frames):
        a = 2 * math.pi * i / frames
        rel = eye0 - target
        # Rodrigues rotation of the eye about ``up``.
        rot = (rel * math.cos(a) + np.cross(up, rel) * math.sin(a) + up * np.dot(up, rel) * (1 - math.cos(a)))
        view = look_at(target + rot, target, up=up).astype(np.float32)
        out.append(Camera(view, np.asarray(K, np.float32), width, height))
    return out


def sequence_camera(seq, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(K [3, 3] scaled so the longer image side is ``size``, w2c [4, 4]) of the first training frame of
    ``seq``: where turntables and animation videos start, as the person was filmed."""
    K, w2c = seq.cameras.frame(seq.split("train")[0])
    K = np.array(K, np.float32)
    K[:2] *= size / max(seq.width, seq.height)
    return K, np.asarray(w2c)


def render_turntable(renderer, params: dict, K: np.ndarray, w2c: np.ndarray, size: int, frames: int,
                     background=(1.0, 1.0, 1.0)) -> list[np.ndarray]:
    """``frames`` float [size, size, 3] renders of ``renderer`` (an ``AvatarRenderer``) posed by ``params``
    from the cameras of :func:`orbit_cameras` (a full turn starting at ``w2c``)."""
    return [renderer.render(params, cam, background) for cam in orbit_cameras(w2c, K, size, size, frames)]


def write_video(path: str | Path, frames: list[np.ndarray], fps: float = 24.0) -> Path:
    """Write float [H, W, 3] frames as an H.264 MP4 (imageio-ffmpeg); falls back to a GIF beside it when
    ffmpeg is unavailable. Returns the written path."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    data = [to_uint8(f) for f in frames]
    try:
        import imageio.v2 as iio2

        tmp = path.with_name(f".{path.stem}.tmp{path.suffix}")
        with iio2.get_writer(tmp, fps=fps, codec="libx264", quality=8, macro_block_size=1,
                             ffmpeg_log_level="error") as w:
            for f in data:
                w.append_data(f)
        tmp.replace(path)
        return path
    except Exception as exc:  # no ffmpeg backend: a GIF still shows the result
        import imageio.v3 as iio

        gif = path.with_suffix(".gif")
        iio.imwrite(gif, np.stack(data), duration=1000 / fps, loop=0)
        print(f"[gma] mp4 writing failed ({exc}); wrote {gif}")
        return gif
