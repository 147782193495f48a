"""Left/right limb swaps of a landmark detector (``gma.video.swaps.resolve_limb_swaps``) on hand-made
landmark tracks of a person turning in place, with the swaps placed where a detector makes them."""

from __future__ import annotations

import numpy as np
import pytest

from gma.video.landmarks import POSE_FLIP
from gma.video.swaps import LIMB_PAIRS, apply_limb_swaps, resolve_limb_swaps

# Body-frame positions (x: the person's left, y: down, z: the person's back) of the landmarks used, left
# side; the right side mirrors x.
_LEFT = {11: (0.18, -0.5, 0.0), 13: (0.22, -0.22, 0.0), 15: (0.24, 0.05, -0.05), 17: (0.25, 0.12, -0.05),
         19: (0.24, 0.13, -0.07), 21: (0.23, 0.1, -0.08), 23: (0.1, 0.0, 0.0), 25: (0.11, 0.42, -0.02),
         27: (0.11, 0.85, 0.0), 29: (0.11, 0.9, 0.05), 31: (0.11, 0.92, -0.12)}


def _person(yaw: float, swing: float) -> np.ndarray:
    """World landmarks [33, 3] (camera axes, hip-centred) of a person facing ``yaw`` (0: the camera) whose
    left arm swings forward by ``swing`` metres and right arm back."""
    p = np.zeros((33, 3))
    for i, (x, y, z) in _LEFT.items():
        for idx, side in ((i, 1), (int(POSE_FLIP[i]), -1)):
            fwd = -side * swing if idx in (15, 16, 17, 18, 19, 20, 21, 22) else 0.0
            p[idx] = (side * x, y, z - fwd)
    c, s = np.cos(yaw), np.sin(yaw)
    rot = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])  # about the vertical axis
    return p @ rot.T


def _turn(n: int = 16, seed: int = 0):
    """A quarter turn to the profile and on (yaw 0 -> 135°) with swinging arms: (pose2d [T, 33, 3] in
    pixels with visibility 1, pose3d [T, 33, 3])."""
    rng = np.random.default_rng(seed)
    yaws = np.radians(np.linspace(0, 135, n))
    p3 = np.stack([_person(y, 0.15 * np.sin(0.5 * t)) for t, y in enumerate(yaws)])
    p3 += rng.normal(0, 0.005, p3.shape)  # a detector's jitter
    p2 = np.concatenate([p3[..., :2] * 200 + 256, np.ones((n, 33, 1))], -1)
    return p2, p3


def _swapped(p2, p3, limb: str, frames: np.ndarray):
    s2, s3, _ = apply_limb_swaps(p2, p3, np.zeros((len(p2), 2, 21, 3)), {limb: frames})
    return s2, s3


@pytest.mark.parametrize("limb", list(LIMB_PAIRS))
def test_a_swap_in_the_profile_frames_is_found(limb):
    """Labels exchanged in the frames around the profile (yaw ~90°), where the two limbs overlap in the
    image: the 3D landmarks' depth tells them apart, and the swap is found there and nowhere else."""
    p2, p3 = _turn()
    truth = np.zeros(len(p2), bool)
    truth[9:12] = True
    s2, s3 = _swapped(p2, p3, limb, truth)
    found = np.ones(len(p2), bool)
    assert np.array_equal(resolve_limb_swaps(s2, s3, found, limb), truth)
    assert not resolve_limb_swaps(p2, p3, found, limb).any()  # a clean track is left alone


def test_a_swap_from_the_first_frame_is_found_by_the_torso():
    """A clip that starts with the arms exchanged: no jump shows it, the elbows' distance to their own
    shoulders does (frontal frames show the shoulders apart)."""
    p2, p3 = _turn()
    truth = np.zeros(len(p2), bool)
    truth[:4] = True
    s2, s3 = _swapped(p2, p3, "arms", truth)
    assert np.array_equal(resolve_limb_swaps(s2, s3, np.ones(len(p2), bool), "arms"), truth)


def test_frames_without_a_detection_are_bridged():
    """Missing frames (NaN landmarks) are never swapped, and the frames either side are linked directly."""
    p2, p3 = _turn()
    truth = np.zeros(len(p2), bool)
    truth[9:12] = True
    s2, s3 = _swapped(p2, p3, "arms", truth)
    found = np.ones(len(p2), bool)
    found[[3, 10]] = False
    s2[~found], s3[~found] = np.nan, np.nan
    expected = truth & found
    assert np.array_equal(resolve_limb_swaps(s2, s3, found, "arms"), expected)
    assert not resolve_limb_swaps(s2, s3, np.zeros(len(p2), bool), "arms").any()


def test_apply_limb_swaps_exchanges_the_limb_and_its_hand_only():
    p2, p3 = _turn(4)
    hands = np.zeros((4, 2, 21, 3))
    hands[:, 0, :, 2] = 1.0  # only the left hand seen
    frames = np.array([False, True, False, False])
    s2, s3, h2 = apply_limb_swaps(p2, p3, hands, {"arms": frames})
    assert np.array_equal(s2[1, 13], p2[1, 14]) and np.array_equal(s3[1, 16], p3[1, 15])
    assert np.array_equal(s2[1, 11], p2[1, 11])  # the shoulders keep their labels
    assert np.array_equal(s2[0], p2[0]) and h2[1, 1, 0, 2] == 1 and h2[0, 0, 0, 2] == 1
    back, _, _ = apply_limb_swaps(s2, s3, h2, {"arms": frames})
    assert np.array_equal(back, p2)


def test_detection_modes_find_the_person_and_keep_their_own_caches(tmp_path, synth_clip):
    """MediaPipe tracking the person and detecting each frame on its own both find the synthetic person;
    a cache written in one mode is not read back as the other's."""
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.video.detect import detect_frames
    from gma.video.frames import read_video

    frames, _ = read_video(synth_clip[1], 0, 3)
    tracked, reused = detect_frames(frames, tmp_path, progress=False, tracking=True)
    assert tracked.found.all() and reused == 0
    single, reused = detect_frames(frames, tmp_path, progress=False, tracking=False)
    assert single.found.all() and reused == 0  # the tracking cache was not taken for a per-frame one
    assert np.abs(single.pose2d[:, 11:13, :2] - tracked.pose2d[:, 11:13, :2]).max() < 10  # same shoulders, px
    _, reused = detect_frames(frames, tmp_path, progress=False, tracking=False)
    assert reused == 3
