"""An orbit camera (target, distance, azimuth, elevation) that produces OpenCV :class:`Camera`s, and
camera paths interpolated between orbit keyframes (for recording)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from gma.core.camera import Camera

__all__ = ["CameraPath", "OrbitCamera"]

_UP = {"y": np.array([0.0, 1.0, 0.0]), "z": np.array([0.0, 0.0, 1.0])}
# The direction the default view looks from: the body's front (Anny faces -Y, SMPL-X +Z).
_FRONT = {"y": np.array([0.0, 0.0, 1.0]), "z": np.array([0.0, -1.0, 0.0])}


@dataclass
class OrbitCamera:
    """Spherical camera around ``target`` [3] (world units). ``azimuth``/``elevation`` in degrees, measured
    from the front of the subject about the ``up_axis``; ``fov_y`` in degrees."""

    target: np.ndarray
    distance: float = 3.0
    azimuth: float = 0.0
    elevation: float = 0.0
    fov_y: float = 40.0
    up_axis: str = "y"

    @staticmethod
    def framing(lo: np.ndarray, hi: np.ndarray, up_axis: str = "y", fov_y: float = 40.0) -> OrbitCamera:
        """A camera that shows the box [lo, hi] whole, from the front."""
        lo, hi = np.asarray(lo, np.float64), np.asarray(hi, np.float64)
        # Fit the largest extent (a standing body's height) with a 10% margin; the diagonal would leave
        # a tall, thin subject small in the frame.
        radius = 0.5 * float(np.max(hi - lo)) or 1.0
        distance = 1.1 * radius / math.tan(math.radians(fov_y) / 2) + 0.5 * float(np.min(hi - lo))
        return OrbitCamera((lo + hi) / 2, distance, 0.0, 0.0, fov_y, up_axis)

    # -- geometry -------------------------------------------------------------------------------------
    def _basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        up, front = _UP[self.up_axis], _FRONT[self.up_axis]
        side = np.cross(up, front)
        return up, front, side

    @property
    def eye(self) -> np.ndarray:
        up, front, side = self._basis()
        a, e = math.radians(self.azimuth), math.radians(self.elevation)
        direction = math.cos(e) * (math.cos(a) * front + math.sin(a) * side) + math.sin(e) * up
        return np.asarray(self.target, np.float64) + self.distance * direction

    def camera(self, width: int, height: int) -> Camera:
        """The OpenCV camera of this orbit state for a ``width`` x ``height`` image."""
        return Camera.look_at(self.eye, self.target, up=tuple(_UP[self.up_axis]), fov_y_deg=self.fov_y,
                              width=width, height=height)

    # -- interaction (pixel deltas of a drag, wheel steps) --------------------------------------------
    def orbit(self, dx: float, dy: float, degrees_per_pixel: float = 0.4) -> None:
        """Drag right turns the view to the right around the subject; drag down looks from above."""
        self.azimuth = (self.azimuth - dx * degrees_per_pixel) % 360.0
        # Stop short of the poles, where look_at's up vector would be parallel to the view direction.
        self.elevation = float(np.clip(self.elevation + dy * degrees_per_pixel, -89.0, 89.0))

    def pan(self, dx: float, dy: float, height: int) -> None:
        """Move the target so that the scene follows the cursor (``height``: image height in pixels)."""
        cam = self.camera(max(height, 1), max(height, 1))
        world_per_pixel = 2 * self.distance * math.tan(math.radians(self.fov_y) / 2) / max(height, 1)
        right, down = cam.viewmat[0, :3], cam.viewmat[1, :3]
        self.target = np.asarray(self.target, np.float64) - world_per_pixel * (dx * right + dy * down)

    def zoom(self, steps: float, factor: float = 1.1) -> None:
        """Positive steps (wheel up) move closer."""
        self.distance = float(np.clip(self.distance * factor ** (-steps), 1e-3, 1e4))

    def copy(self) -> OrbitCamera:
        return replace(self, target=np.array(self.target, np.float64))


def _lerp_angle(a: float, b: float, t: float) -> float:
    d = (b - a + 180.0) % 360.0 - 180.0  # the short way round
    return a + t * d


@dataclass
class CameraPath:
    """Orbit keyframes at times ``times`` (seconds, increasing). Between keys the state is interpolated
    linearly (angles the short way round, distance geometrically)."""

    keys: list[OrbitCamera]
    times: list[float]

    @staticmethod
    def turntable(start: OrbitCamera, seconds: float, turns: float = 1.0) -> CameraPath:
        """A full orbit around the target at ``start``'s elevation and distance."""
        keys, times = [], []
        steps = max(4, int(8 * turns))
        for i in range(steps + 1):
            k = start.copy()
            k.azimuth = start.azimuth + 360.0 * turns * i / steps
            keys.append(k)
            times.append(seconds * i / steps)
        return CameraPath(keys, times)

    @property
    def duration(self) -> float:
        return self.times[-1] if self.times else 0.0

    def add(self, cam: OrbitCamera, time: float) -> None:
        if self.times and time <= self.times[-1]:
            raise ValueError(f"keyframe time {time} must be after {self.times[-1]}")
        self.keys.append(cam.copy())
        self.times.append(float(time))

    def at(self, time: float) -> OrbitCamera:
        if not self.keys:
            raise ValueError("camera path has no keyframes")
        if len(self.keys) == 1 or time <= self.times[0]:
            return self.keys[0].copy()
        if time >= self.times[-1]:
            return self.keys[-1].copy()
        i = int(np.searchsorted(self.times, time, side="right")) - 1
        a, b = self.keys[i], self.keys[i + 1]
        t = (time - self.times[i]) / (self.times[i + 1] - self.times[i])
        # Unwrapped azimuths (turntable keys go past 360) interpolate as given; otherwise the short way.
        az = a.azimuth + t * (b.azimuth - a.azimuth) if abs(b.azimuth - a.azimuth) <= 180 else \
            _lerp_angle(a.azimuth, b.azimuth, t)
        return OrbitCamera(
            target=(1 - t) * np.asarray(a.target) + t * np.asarray(b.target),
            distance=math.exp((1 - t) * math.log(a.distance) + t * math.log(b.distance)),
            azimuth=az,
            elevation=(1 - t) * a.elevation + t * b.elevation,
            fov_y=(1 - t) * a.fov_y + t * b.fov_y,
            up_axis=a.up_axis,
        )
