"""What the synthetic camera sees: per-frame Anny poses, facial actions and cameras for each preset.

- ``turn`` (PeopleSnapshot-like): a static camera in front; the person turns slowly in an A-pose, one
  full turn over the training frames. ``test_pose``: walking and waving poses never seen in training,
  facing various directions. ``test_view``: A-poses between the training angles, seen from cameras
  above and below the training one (which stays at chest height).
- ``motion`` (X-Humans-like): a static camera; the person walks, waves and talks while turning once
  around. ``test_pose``: novel combinations (waving while walking, mirrored arm poses). ``test_view``:
  training-like poses from elevated and lowered cameras.

World frame: Anny's (Z up, the person faces −Y at zero rotation, metres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gma.body.motions import motion
from gma.data.cameras import look_at

__all__ = ["PRESETS", "Shots", "make_shots"]

PRESETS = ("turn", "motion")
_TARGET_Z = -0.05  # roughly the middle of an adult Anny body (feet near −0.87, head top near +0.76)


@dataclass
class Shots:
    """pose [T, 104, 4, 4], facial_actions [T, 52], K [3, 3] (shared), w2c [T, 4, 4], splits by name."""

    pose: np.ndarray
    facial_actions: np.ndarray
    K: np.ndarray
    w2c: np.ndarray
    splits: dict[str, list[int]]


def _rot_z(angle: float) -> np.ndarray:
    c, s = math.cos(angle), math.sin(angle)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    return m


def _turned(pose: np.ndarray, angle: float) -> np.ndarray:
    """``pose`` [J, 4, 4] with the whole body turned by ``angle`` about the vertical through the root."""
    out = pose.copy()
    out[0] = _rot_z(angle) @ pose[0]
    return out


def _camera(distance: float, elevation_deg: float, azimuth_deg: float = 0.0) -> np.ndarray:
    el, az = math.radians(elevation_deg), math.radians(azimuth_deg)
    eye = [
        distance * math.cos(el) * math.sin(az),
        -distance * math.cos(el) * math.cos(az),
        _TARGET_Z + 0.25 + distance * math.sin(el),
    ]
    return look_at(eye, [0.0, 0.0, _TARGET_Z], up=[0.0, 0.0, 1.0])


def _mix(
    a: np.ndarray, b: np.ndarray, bone_names: tuple[str, ...], bones_from_b: tuple[str, ...]
) -> np.ndarray:
    """Pose ``a`` with the deltas of bones whose names start with one of ``bones_from_b`` taken from ``b``."""
    out = a.copy()
    for j, name in enumerate(bone_names):
        if name.startswith(bones_from_b):
            out[j] = b[j]
    return out


def make_shots(
    preset: str,
    body,
    width: int,
    height: int,
    n_train: int,
    n_pose: int,
    n_view: int,
    rng: np.random.Generator,
) -> Shots:
    """Poses and cameras of ``preset`` for the Anny ``body`` (for bone and facial action names)."""
    if preset not in PRESETS:
        raise ValueError(f"unknown synth preset {preset!r}; choose one of {', '.join(PRESETS)}")
    if n_train < 1 or n_pose < 0 or n_view < 0:
        raise ValueError("need at least one training frame and non-negative test frame counts")
    names = body.bone_names
    n_fa = body.param_spaces["expression"].size
    f = 1.5 * height  # the person fills ~80 % of the image height at 3 m
    K = np.array([[f, 0.0, width / 2], [0.0, f, height / 2], [0.0, 0.0, 1.0]])
    distance = 3.0
    train_cam = _camera(distance, 0.0)
    walk = motion("walk", 48, body).pose.numpy().astype(np.float64)
    wave = motion("wave", 48, body).pose.numpy().astype(np.float64)

    poses, faces, cams = [], [], []
    if preset == "turn":
        turn = motion("turn", n_train, body)
        poses += list(turn.pose.numpy().astype(np.float64))
        faces += [np.zeros(n_fa)] * n_train
    else:
        parts = (
            motion("walk", max(1, n_train // 3), body),
            motion("wave", max(1, n_train // 3), body),
            motion("expressions", n_train - 2 * max(1, n_train // 3), body),
        )
        seq_pose = np.concatenate([m.pose.numpy() for m in parts])[:n_train].astype(np.float64)
        seq_fa = np.concatenate([m.expression.numpy() for m in parts])[:n_train].astype(np.float64)
        for t in range(n_train):
            poses.append(_turned(seq_pose[t], 2 * math.pi * t / n_train))
            faces.append(seq_fa[t])
    cams += [train_cam] * n_train

    # Novel poses: never in the training set, facing directions spread around the circle.
    for k in range(n_pose):
        angle = 2 * math.pi * (k + rng.uniform(0.2, 0.8)) / max(n_pose, 1)
        src = walk[rng.integers(len(walk))]
        if preset == "turn":
            novel = src if k % 2 == 0 else wave[12 + rng.integers(24)]
        else:
            # Waving while walking, or the walk with the arms from a wave frame: combinations the
            # training clip never shows.
            novel = _mix(
                src,
                wave[12 + rng.integers(24)],
                names,
                ("upperarm01.R", "lowerarm01.R", "wrist.R", "shoulder01.R", "clavicle.R"),
            )
        poses.append(_turned(novel, angle))
        faces.append(np.zeros(n_fa))
        cams.append(train_cam)

    # Novel views: training-like poses seen from above / below / closer than the training camera.
    for k in range(n_view):
        t = rng.integers(n_train)
        angle = rng.uniform(0, 2 * math.pi) if preset == "turn" else 0.0
        poses.append(_turned(poses[t], angle) if preset == "turn" else poses[t])
        faces.append(faces[t])
        elevation = (35.0, -20.0)[k % 2] + rng.uniform(-5, 5)
        cams.append(_camera(distance * rng.uniform(0.85, 1.1), elevation, rng.uniform(-40, 40)))

    splits = {
        "train": list(range(n_train)),
        "test_pose": list(range(n_train, n_train + n_pose)),
        "test_view": list(range(n_train + n_pose, n_train + n_pose + n_view)),
    }
    return Shots(
        np.stack(poses).astype(np.float32), np.stack(faces).astype(np.float32), K, np.stack(cams), splits
    )
