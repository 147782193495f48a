"""The camera of a video import (gma.video.camera): a user's intrinsics file, undistortion of distorted
frames (straight lines come out straight), and the intrinsics through --downscale."""

from __future__ import annotations

import json

import numpy as np
import pytest

cv2 = pytest.importorskip("cv2", reason="the video extra (pip install 'gma[video]') brings OpenCV")

from gma.data.importers._common import scale_cameras  # noqa: E402
from gma.video.camera import CameraIntrinsics, Undistortion, load_intrinsics, static_camera  # noqa: E402

W, H = 160, 120
# A wide lens: barrel distortion moving the corners by ~10 px, a little tangential distortion.
LENS = CameraIntrinsics(fx=110.0, fy=112.0, cx=81.3, cy=58.6, dist=(-0.28, 0.07, 0.002, -0.0015, 0.0))
LINE_PX = 0.3  # centre lines of the undistorted grid stay within this of a straight line (px)


def _distorted_grid(intr: CameraIntrinsics, step: int = 20) -> np.ndarray:
    """What the lens sees of a grid of dark lines straight in the undistorted image: each distorted pixel's
    undistorted position (cv2.undistortPoints), anti-aliased lines of 2 px width. float32 [H, W]."""
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    pts = np.stack([xx.ravel(), yy.ravel()], -1)[:, None]
    K = intr.opencv_K()
    und = cv2.undistortPoints(pts, K, np.asarray(intr.dist), P=K,
                              criteria=(cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 50, 1e-6))
    u, v = und[:, 0, 0].reshape(H, W), und[:, 0, 1].reshape(H, W)

    def near(c):
        return np.clip(1.5 - np.abs(c - np.round(c / step) * step), 0, 1)

    return np.maximum(near(u), near(v)).astype(np.float32)


def _worst_bend(img: np.ndarray, step: int = 20, axis: int = 0) -> float:
    """Largest distance (px) of a grid line's centre from its best straight line, over the lines that run
    along ``axis`` = 0 (horizontal lines) of ``img``, measured away from the frame's edges and the crossings."""
    if axis == 1:
        img = img.T
    h, w = img.shape
    worst = 0.0
    for y0 in range(step, h - step // 2, step):
        xs, ys = [], []
        for x in range(12, w - 12):
            if min(x % step, step - x % step) < 5:
                continue  # a crossing line would pull the centroid
            band = np.arange(max(0, y0 - 8), min(h, y0 + 9))
            wgt = img[band, x]
            if wgt.sum() < 0.5:
                continue
            xs.append(x)
            ys.append(float((wgt * band).sum() / wgt.sum()))
        if len(xs) < 10:
            continue
        fit = np.polyfit(xs, ys, 1)
        worst = max(worst, float(np.abs(np.polyval(fit, xs) - ys).max()))
    return worst


@pytest.mark.parametrize("axis", [0, 1], ids=["horizontal", "vertical"])
def test_undistortion_straightens_lines(axis):
    grid = _distorted_grid(LENS)
    assert _worst_bend(grid, axis=axis) > 2.0  # the lens bends them
    straight = Undistortion(LENS, W, H)(grid)
    assert straight.dtype == np.float32 and straight.shape == grid.shape
    assert _worst_bend(straight, axis=axis) < LINE_PX


def test_undistortion_keeps_uint8_frames_and_the_principal_point():
    """An RGB uint8 frame stays uint8 [H, W, 3]; the pixel at the principal point does not move."""
    img = np.zeros((H, W, 3), np.uint8)
    img[int(LENS.cy), int(LENS.cx)] = 255
    out = Undistortion(LENS, W, H)(img)
    assert out.dtype == np.uint8 and out.shape == img.shape
    assert np.unravel_index(out[..., 0].argmax(), (H, W)) == (int(LENS.cy), int(LENS.cx))


def test_intrinsics_convention_and_downscale(tmp_path):
    """cx, cy in OpenCV's convention gain half a pixel (GMA's pixel centres are at +0.5); --downscale 2 halves
    the focal lengths and the principal point in GMA's convention."""
    path = tmp_path / "cam.json"
    path.write_text(json.dumps({"fx": 1400, "fy": 1390.5, "cx": 959.5, "cy": 539.5, "k1": -0.1, "width": 1920,
                                "height": 1080}))
    intr = load_intrinsics(path)
    assert intr.dist == (-0.1, 0.0, 0.0, 0.0, 0.0) and intr.distorted
    np.testing.assert_allclose(intr.K(), [[1400, 0, 960], [0, 1390.5, 540], [0, 0, 1]])
    cams = scale_cameras(static_camera(1920, 1080, intr.K(), np.zeros(3)), 2)
    assert (cams.width, cams.height) == (960, 540)
    np.testing.assert_allclose(cams.K[0], [[700, 0, 480], [0, 695.25, 270], [0, 0, 1]])
    with pytest.raises(ValueError, match="1920x1080"):
        intr.check_frame(1280, 720)
    # A phone's portrait clip is read upright (1080x1920): the message says the frames are turned.
    with pytest.raises(ValueError, match="turned by a quarter.*upright frames"):
        intr.check_frame(1080, 1920)
