"""Smoothing landmark tracks over time without lag.

A landmark detector run frame by frame jitters; the usual cure, a causal filter (MediaPipe's own
``smooth_landmarks``, a one-euro filter), trails a moving person: on a turn in place sampled at 16
frames per turn it left the shoulders 15-20° of turn behind the truth in most frames (docs/fitting.md).
An import has the whole clip at hand, so each frame is smoothed from the frames on both sides: a
weighted least-squares quadratic over a short window, evaluated at the frame. A quadratic follows a
steady turn or a swing without lag or shrinkage; the confidence of each detection weights it; and one
robust pass takes the weight off detections far from their neighbours (a landmark that jumped to the
wrong limb for a frame), so they are replaced rather than smeared over the frames around them.

Its weak spot is the clip's ends, where the window is one-sided and the quadratic extrapolates: on the
iPER turn the last two frames came out 2-3 dB worse, which is why the import leaves it off by default.
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["SMOOTH_RADIUS", "smooth_landmarks", "smooth_tracks"]

SMOOTH_RADIUS = 3  # frames either side a frame is smoothed over
_SIGMA = 2.0  # frames: Gaussian fall-off of the neighbours' weight
# Pull of the slope and the curvature toward 0, which decides only where a window holds too few detections
# to fit them (one or two); small enough to leave a well-sampled window's fit as it is.
_RIDGE = np.diag([0.0, 1e-9, 1e-6])
# Robust pass: a detection k times this far (× the person's size) from its smoothed track keeps
# exp(−k²/2) of its weight (Welsch): 61 % at 3 %, next to nothing at 10 %.
_OUTLIER = 0.03


def _fit_at_centre(x: np.ndarray, w: np.ndarray, radius: int) -> np.ndarray:
    """Weighted quadratic fits over ``radius`` frames either side, evaluated at each frame.
    ``x`` [T, N, D], ``w`` [T, N] -> [T, N, D]; NaN where a frame's window has no weight at all."""
    T = len(x)
    offsets = np.arange(-radius, radius + 1)
    basis = np.stack([np.ones_like(offsets), offsets / radius, (offsets / radius) ** 2], 1).astype(np.float64)
    gauss = np.exp(-0.5 * (offsets / _SIGMA) ** 2)
    idx = np.arange(T)[:, None] + offsets[None]                                   # [T, K]
    inside = (idx >= 0) & (idx < T)
    idx = np.clip(idx, 0, T - 1)
    wk = w[idx] * (gauss * inside)[..., None]                                   # [T, K, N]
    xk = np.nan_to_num(x[idx])                                                  # [T, K, N, D]
    A = np.einsum("tkn,ki,kj->tnij", wk, basis, basis) + _RIDGE
    b = np.einsum("tkn,ki,tknd->tnid", wk, basis, xk)
    weight = wk.sum(1)                                                          # [T, N]
    A[weight <= 0] = np.eye(3)  # (no data: any solvable system; the result is masked below)
    coef = np.linalg.solve(A, b)                                                # [T, N, 3, D]
    out = coef[:, :, 0]
    out[weight <= 0] = np.nan
    return out


def smooth_tracks(x: np.ndarray, weight: np.ndarray, size: np.ndarray | None = None,
                  radius: int = SMOOTH_RADIUS) -> np.ndarray:
    """Tracks ``x`` [T, N, D] (N points, D coordinates) smoothed over time, each frame from a weighted
    quadratic over ``radius`` frames either side. ``weight`` [T, N] >= 0 is each detection's confidence
    (0: missing; NaN in ``x`` counts as missing). ``size`` [T], the person's size in ``x``'s units, turns
    on the robust pass (detections more than a few % of it from their smoothed track lose most of their
    weight).
    Points with no detection within ``radius`` frames keep their input value (NaN stays NaN)."""
    x = np.asarray(x, np.float64)
    if x.ndim != 3 or weight.shape != x.shape[:2]:
        raise ValueError(f"smooth_tracks: tracks [T, N, D] and weights [T, N], got {x.shape} and {weight.shape}")
    w = np.where(np.isfinite(x).all(-1), np.clip(np.nan_to_num(weight), 0, None), 0.0)
    if len(x) < 2 or radius < 1:
        return x.copy()
    out = _fit_at_centre(x, w, radius)
    if size is not None:
        miss = np.linalg.norm(np.nan_to_num(x - out), axis=-1) / (_OUTLIER * np.asarray(size, np.float64)[:, None])
        out = _fit_at_centre(x, w * np.exp(-0.5 * miss**2), radius)
    return np.where(np.isfinite(out), out, x)


def _person_size(points: np.ndarray) -> np.ndarray:
    """[T] bounding-box diagonal of each frame's points [T, N, D] (NaN ignored; the clip's median where a
    frame has none)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # (all-NaN frames)
        d = np.linalg.norm(np.nanmax(points, 1) - np.nanmin(points, 1), axis=-1)
    good = np.isfinite(d) & (d > 0)
    return np.where(good, d, np.median(d[good]) if good.any() else 1.0)


def smooth_landmarks(pose2d: np.ndarray, pose3d: np.ndarray, hands2d: np.ndarray, found: np.ndarray,
                     radius: int = SMOOTH_RADIUS):
    """A clip's landmarks (shapes as in :class:`~gma.video.detect.Detections`, left/right swaps already
    resolved) with their positions smoothed over ``radius`` frames either side, weighted by visibility
    (pose) or presence (hands), robust to single-frame jumps. Visibility, presence and frames without a
    detection are left as they are. Returns new arrays."""
    p2, p3, h2 = pose2d.copy(), pose3d.copy(), hands2d.copy()
    if radius < 1 or not found.any():
        return p2, p3, h2
    vis = np.where(found[:, None], np.clip(np.nan_to_num(pose2d[..., 2]), 0, 1), 0.0)
    size_px = _person_size(np.where(found[:, None, None], pose2d[..., :2], np.nan))
    p2[..., :2] = smooth_tracks(pose2d[..., :2], vis, size_px, radius)
    p3[:] = smooth_tracks(pose3d, vis, _person_size(np.where(found[:, None, None], pose3d, np.nan)), radius)
    for side in range(hands2d.shape[1]):
        present = (hands2d[:, side, :, 2] > 0) & found[:, None]
        smoothed = smooth_tracks(hands2d[:, side, :, :2], present.astype(np.float64), size_px, radius)
        h2[:, side, :, :2] = np.where(present[..., None], smoothed, hands2d[:, side, :, :2])  # absent stays absent
    keep = ~found
    p2[keep], p3[keep], h2[keep] = pose2d[keep], pose3d[keep], hands2d[keep]
    return p2, p3, h2
