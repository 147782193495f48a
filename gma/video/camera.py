"""The static pinhole camera of a video import.

Assumptions (documented for users in ``gma import video --help``): one camera that does not move or
zoom. Without a camera file: square pixels, no skew, no lens distortion, principal point at the image
centre, and a focal length from the user (``--focal``, pixels) or the image's longer side — a 53°
field of view across it, between a phone's main camera (~65–70°) and a zoomed-in shot. A wrong focal
length mostly trades against the person's distance, so the 2D fit stays good while the recovered depth
and perspective are off. With a camera file (``--camera``, :func:`load_intrinsics`): the user's
calibration — focal lengths, principal point and optionally OpenCV's distortion coefficients; distorted
frames are undistorted once, before anything looks at them (:class:`Undistortion`), and the sequence
holds the undistorted frames with the same ``K``.

World frame: Anny's (Z up, metres). The camera looks along world +Y from behind the person, who faces
−Y (Anny's front) at zero rotation; after the fit the world is shifted so the person's median root
position is the origin.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.camera import read_camera_json
from gma.core.errors import InputError
from gma.data.cameras import Cameras

__all__ = ["CAMERA_FROM_WORLD", "CameraIntrinsics", "Undistortion", "default_focal", "intrinsics",
           "load_intrinsics", "static_camera"]

# OpenCV camera axes (x right, y down, z forward) in Anny's world: x = X, y = −Z, z = +Y.
CAMERA_FROM_WORLD = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], np.float64)


def default_focal(width: int, height: int) -> float:
    """Focal length in pixels when the user gives none: the longer image side."""
    return float(max(width, height))


def intrinsics(width: int, height: int, focal: float | None = None) -> np.ndarray:
    """K [3, 3]: focal ``focal`` (pixels; default :func:`default_focal`), principal point at the centre
    (pixel (x, y) has its centre at (x + 0.5, y + 0.5), so the centre is (W / 2, H / 2))."""
    f = default_focal(width, height) if focal is None else float(focal)
    if not np.isfinite(f) or f <= 0:
        raise ValueError(f"focal length must be a positive number of pixels, got {focal}")
    return np.array([[f, 0, width / 2], [0, f, height / 2], [0, 0, 1]], np.float64)


def static_camera(width: int, height: int, K: np.ndarray, centre: np.ndarray) -> Cameras:
    """Cameras of the sequence: ``K`` and a world→camera matrix whose camera sits at world position
    ``centre`` [3] looking along +Y (see the module docstring)."""
    w2c = np.eye(4)
    w2c[:3, :3] = CAMERA_FROM_WORLD
    w2c[:3, 3] = -CAMERA_FROM_WORLD @ np.asarray(centre, np.float64)
    return Cameras(width, height, np.asarray(K, np.float64)[None], w2c[None])


DISTORTION_KEYS = ("k1", "k2", "p1", "p2", "k3")  # OpenCV's order of the first five coefficients
_REQUIRED = ("fx", "fy", "cx", "cy")
# Beyond these the file is taken for a mistake: a pixel moved by more than a quarter of the frame's
# diagonal, or more than half the undistorted frame showing nothing of the video.
_MAX_SHIFT_OF_DIAGONAL = 0.25
_MIN_COVERED = 0.5


@dataclass(frozen=True)
class CameraIntrinsics:
    """A user's calibration of the video's camera, in pixels of the original video, as OpenCV's
    calibration writes it: ``cx, cy`` with the centre of the top-left pixel at (0, 0). ``dist`` holds
    (k1, k2, p1, p2, k3), zeros when none is given; ``width``/``height``: the frame size the calibration
    is for, when the file says (checked against the video)."""

    fx: float
    fy: float
    cx: float
    cy: float
    dist: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)
    width: int | None = None
    height: int | None = None
    source: str = "camera file"

    @property
    def distorted(self) -> bool:
        return any(d != 0.0 for d in self.dist)

    def opencv_K(self) -> np.ndarray:
        """K [3, 3] in OpenCV's pixel convention (what ``cv2`` and the distortion model take)."""
        return np.array([[self.fx, 0, self.cx], [0, self.fy, self.cy], [0, 0, 1]], np.float64)

    def K(self) -> np.ndarray:
        """K [3, 3] in GMA's convention (pixel (x, y) has its centre at (x + 0.5, y + 0.5)): the principal
        point moves by half a pixel. This is the ``K`` of the undistorted frames too."""
        K = self.opencv_K()
        K[:2, 2] += 0.5
        return K

    def check_frame(self, width: int, height: int) -> None:
        """Refuse a calibration that does not fit a ``width``×``height`` video (one line naming the file)."""
        if self.width is not None and (self.width, self.height) == (height, width) and width != height:
            # A phone's portrait clip: landscape frames stored with a display rotation, which reading applies.
            raise InputError(f"{self.source}: the calibration is for {self.width}x{self.height} frames and the video's "
                             f"are {width}x{height}, turned by a quarter: a phone's portrait clip is read upright, "
                             "so give the intrinsics of the upright frames (fx and fy swapped, cx and cy as seen in "
                             "the turned picture)")
        if self.width is not None and (self.width, self.height) != (width, height):
            raise InputError(f"{self.source}: the calibration is for {self.width}x{self.height} frames, the video is "
                             f"{width}x{height} (give intrinsics in pixels of the original video)")
        if not (-0.5 <= self.cx <= width - 0.5 and -0.5 <= self.cy <= height - 0.5):
            raise InputError(f"{self.source}: principal point ({self.cx:g}, {self.cy:g}) lies outside the "
                             f"{width}x{height} frame")


def load_intrinsics(path: str | os.PathLike) -> CameraIntrinsics:
    """Read a camera file: a JSON object with ``fx``, ``fy``, ``cx``, ``cy`` (pixels of the original
    video, OpenCV convention), optional distortion ``k1``, ``k2``, ``p1``, ``p2``, ``k3`` (OpenCV's
    model; missing ones are 0) and optional ``width``, ``height``. Anything else is refused, so a typo
    does not silently drop a coefficient. Values are checked here; the fit with the frame in
    :meth:`CameraIntrinsics.check_frame` and :class:`Undistortion`."""
    path = Path(path)
    raw = read_camera_json(path, "fx, fy, cx, cy (and optionally k1, k2, p1, p2, k3)")
    missing = [k for k in _REQUIRED if k not in raw]
    if missing:
        raise InputError(f"{path}: missing {', '.join(missing)} (a camera file holds fx, fy, cx, cy in pixels, and "
                         "optionally k1, k2, p1, p2, k3)")
    unknown = sorted(set(raw) - set(_REQUIRED) - set(DISTORTION_KEYS) - {"width", "height"})
    if unknown:
        raise InputError(f"{path}: unknown key(s) {', '.join(unknown)} (expected fx, fy, cx, cy, k1, k2, p1, p2, k3, "
                         "width, height)")
    values = {}
    for key in (*_REQUIRED, *DISTORTION_KEYS):
        v = raw.get(key, 0.0)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            raise InputError(f"{path}: {key} must be a finite number, got {v!r}")
        values[key] = float(v)
    for key in ("fx", "fy"):
        if values[key] <= 0:
            raise InputError(f"{path}: {key} must be a positive focal length in pixels, got {values[key]:g}")
    if max(values["fx"], values["fy"]) > 20 * min(values["fx"], values["fy"]):
        raise InputError(f"{path}: fx {values['fx']:g} and fy {values['fy']:g} differ by more than 20 times")
    size = []
    for key in ("width", "height"):
        v = raw.get(key)
        if v is not None and (isinstance(v, bool) or not isinstance(v, int) or v <= 0):
            raise InputError(f"{path}: {key} must be a positive whole number of pixels, got {v!r}")
        size.append(v)
    if (size[0] is None) != (size[1] is None):
        raise InputError(f"{path}: give both width and height, or neither")
    return CameraIntrinsics(values["fx"], values["fy"], values["cx"], values["cy"],
                            tuple(values[k] for k in DISTORTION_KEYS), size[0], size[1], str(path))


class Undistortion:
    """Undistorts ``width``×``height`` frames of camera ``intr``: the pixel map is computed once here
    (``cv2.initUndistortRectifyMap``, same ``K`` before and after) and every frame is one
    ``cv2.remap``. Refuses (one line naming the file) distortion that folds the frame over itself,
    moves a pixel by more than a quarter of the frame's diagonal or leaves most of the undistorted frame
    without video. Needs OpenCV (``gma[video]``)."""

    def __init__(self, intr: CameraIntrinsics, width: int, height: int):
        try:
            import cv2
        except ImportError as exc:
            from gma.video.detect import MissingExtraError

            raise MissingExtraError(f"{intr.source}: undistorting frames needs OpenCV: pip install 'gma[video]' "
                                    "(or give a camera file without distortion)") from exc

        self.width, self.height = width, height
        K = intr.opencv_K()
        self.map_x, self.map_y = cv2.initUndistortRectifyMap(K, np.asarray(intr.dist), None, K, (width, height),
                                                             cv2.CV_32FC1)
        self._check(intr)

    def _check(self, intr: CameraIntrinsics) -> None:
        mx, my = self.map_x.astype(np.float64), self.map_y.astype(np.float64)
        yy, xx = np.mgrid[0:self.height, 0:self.width]
        what = f"{intr.source}: distortion (k1, k2, p1, p2, k3) = {', '.join(f'{d:g}' for d in intr.dist)} is absurd"
        if not (np.isfinite(mx).all() and np.isfinite(my).all()):
            raise InputError(f"{what} for this {self.width}x{self.height} frame (the model has no solution)")
        folds = (np.diff(mx, axis=1) <= 0).any() or (np.diff(my, axis=0) <= 0).any()
        if folds:
            raise InputError(f"{what}: it folds the {self.width}x{self.height} frame over itself")
        shift = float(np.hypot(mx - xx, my - yy).max())
        if shift > _MAX_SHIFT_OF_DIAGONAL * math.hypot(self.width, self.height):
            raise InputError(f"{what}: it moves pixels by up to {shift:.0f} px in a {self.width}x{self.height} frame")
        inside = (mx >= -0.5) & (mx <= self.width - 0.5) & (my >= -0.5) & (my <= self.height - 0.5)
        if inside.mean() < _MIN_COVERED:
            raise InputError(f"{what}: only {inside.mean():.0%} of the undistorted frame would show the video")

    def __call__(self, image: np.ndarray) -> np.ndarray:
        """The undistorted ``image`` [H, W(, C)], same dtype; pixels that see outside the video are 0."""
        import cv2

        if image.shape[:2] != (self.height, self.width):
            raise ValueError(f"frame is {image.shape[1]}x{image.shape[0]}, the undistortion map {self.width}x"
                             f"{self.height}")
        return cv2.remap(image, self.map_x, self.map_y, cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                         borderValue=0)
