"""Lag-free smoothing of landmark tracks (``gma.video.smooth``) on known tracks."""

from __future__ import annotations

import numpy as np
import pytest

from gma.video.smooth import smooth_tracks


def _track(values: np.ndarray) -> np.ndarray:
    """[T] values as one point's track with two coordinates [T, 1, 2] (the second the negative)."""
    return np.stack([values, -values], -1)[:, None]


def test_a_steady_motion_passes_without_lag():
    """A quadratic path (a steady acceleration) comes out as it went in, ends included: no lag, no shrink."""
    t = np.arange(20.0)
    x = _track(3 + 2 * t + 0.1 * t**2)
    assert np.abs(smooth_tracks(x, np.ones((20, 1))) - x).max() < 0.05  # (the ridge's pull at the ends)


def test_jitter_is_taken_out_of_a_turn():
    """A shoulder's x over a turn in place (16 frames a turn) plus detector jitter: the smoothed track is
    closer to the true one than the detections, and lags it nowhere."""
    rng = np.random.default_rng(0)
    t = np.arange(32.0)
    truth = _track(20 * np.cos(2 * np.pi * t / 16))
    seen = truth + rng.normal(0, 1.5, truth.shape)
    out = smooth_tracks(seen, np.ones((32, 1)))
    assert np.sqrt(((out - truth) ** 2).mean()) < 0.8 * np.sqrt(((seen - truth) ** 2).mean())
    clean = smooth_tracks(truth, np.ones((32, 1)))
    assert np.abs(clean - truth).max() < 0.5  # 2.5 % of the swing at most


def test_a_detection_that_jumped_is_replaced_not_smeared():
    """One frame's landmark on the wrong limb, 30 px off a 200 px person: with the person's size the robust
    pass gives it next to no weight, so that frame comes back near the track and its neighbours stay on it."""
    t = np.arange(15.0)
    truth = _track(100 + 3 * t)
    seen = truth.copy()
    seen[7] += 30.0
    plain = smooth_tracks(seen, np.ones((15, 1)))
    robust = smooth_tracks(seen, np.ones((15, 1)), size=np.full(15, 200.0))
    assert np.abs(robust - truth).max() < 1.5
    assert np.abs(robust - truth).max() < 0.5 * np.abs(plain - truth).max()


def test_missing_detections_are_filled_and_weights_count():
    """Missing frames (NaN or weight 0) get the track's value from their neighbours; a point never seen
    stays NaN; a detection with a small weight pulls less than one with a large weight."""
    t = np.arange(12.0)
    x = np.concatenate([_track(5 * t), np.full((12, 1, 2), np.nan)], 1)   # [T, 2 points, 2]
    w = np.ones((12, 2))
    x[4, 0] = np.nan
    w[6, 0] = 0.0
    x[6, 0] = 1e6  # ignored: weight 0
    out = smooth_tracks(x, w)
    assert np.allclose(out[:, 0], _track(5 * t)[:, 0], atol=1e-3)
    assert np.isnan(out[:, 1]).all()
    off = _track(5 * t)
    off[8] += 10.0
    low, high = w.copy(), w.copy()
    low[8, 0], high[8, 0] = 0.1, 10.0
    assert abs(smooth_tracks(off, low[:, :1])[8, 0, 0] - 40) < abs(smooth_tracks(off, high[:, :1])[8, 0, 0] - 40)


def test_short_clips_and_bad_shapes():
    one = _track(np.array([3.0]))
    assert np.array_equal(smooth_tracks(one, np.ones((1, 1))), one)
    with pytest.raises(ValueError, match=r"tracks \[T, N, D\]"):
        smooth_tracks(np.zeros((5, 2)), np.ones((5, 2)))
    with pytest.raises(ValueError, match="weights"):
        smooth_tracks(np.zeros((5, 2, 3)), np.ones((5, 3)))


def test_a_clip_without_hands_or_with_missed_frames_smooths_cleanly():
    """smooth_landmarks on a clip where no hand is ever seen and one frame has no person: the hands stay
    absent (zeros, presence 0), the missed frame stays as detected (NaN), visibility is kept, and the
    found frames' pose comes out finite and on the (straight) track."""
    from gma.video.smooth import smooth_landmarks

    T = 9
    t = np.arange(T, dtype=float)
    pose2d = np.zeros((T, 33, 3))
    pose2d[..., 0] = 100 + 4 * t[:, None] + np.arange(33)  # every landmark moving right at 4 px a frame
    pose2d[..., 1] = 200 + np.arange(33)
    pose2d[..., 2] = 0.9
    pose3d = pose2d.copy() / 100
    hands2d = np.zeros((T, 2, 21, 3))
    found = np.ones(T, bool)
    found[4] = False
    pose2d[4], pose3d[4] = np.nan, np.nan
    p2, p3, h2 = smooth_landmarks(pose2d, pose3d, hands2d, found)
    assert np.array_equal(h2, hands2d)
    assert np.isnan(p2[4]).all() and np.isnan(p3[4]).all()
    assert np.isfinite(p2[found]).all() and np.isfinite(p3[found]).all()
    assert np.allclose(p2[found], pose2d[found], atol=1e-3) and np.array_equal(p2[..., 2][found], pose2d[..., 2][found])
    same = smooth_landmarks(pose2d, pose3d, hands2d, found, radius=0)
    assert all(np.array_equal(a, b, equal_nan=True) for a, b in zip(same, (pose2d, pose3d, hands2d), strict=True))
