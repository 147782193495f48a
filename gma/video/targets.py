"""Fitting targets built from detections: 2D points with confidences in the model's point order, and
3D directions between model points (the body's bones from the pose landmarks, the face's from the face
mesh): the inputs of the losses in ``gma.video.fit``."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.video.landmarks import (
    BONE_PAIR_WEIGHTS,
    BONE_PAIRS,
    FACE_PAIR_WEIGHTS,
    FACE_PAIRS,
    FACE_POINTS,
    HAND_POINTS,
    POSE_POINTS,
    POSE_WEIGHTS,
)

__all__ = ["FitTargets", "build_targets"]

HAND_WEIGHT = 0.5  # hand landmarks are small and noisier than the body's


@dataclass
class FitTargets:
    """T frames, P model points, B bone pairs.

    uv:      [T, P, 2] target pixel positions (0 where unknown)
    conf:    [T, P] weight (0 = unknown) — visibility × table weight
    dirs3d:  [T, B, 3] unit directions in camera axes: the bones' (BONE_PAIRS, from MediaPipe's world
             landmarks), then the face's (FACE_PAIRS, from the face mesh)
    conf3d:  [T, B] weight (0 = unknown)
    pair_idx: [B, 2] model point indices of the pairs' ends
    pair_w:  [B] weight of each pair (BONE_PAIR_WEIGHTS, FACE_PAIR_WEIGHTS)
    scale:   [T] person size in pixels (landmark bounding-box diagonal), normalises the 2D error
    found:   [T] bool
    """

    uv: torch.Tensor
    conf: torch.Tensor
    dirs3d: torch.Tensor
    conf3d: torch.Tensor
    pair_idx: torch.Tensor
    pair_w: torch.Tensor
    scale: torch.Tensor
    found: torch.Tensor


def build_targets(point_names: list[str], pose2d: np.ndarray, pose3d: np.ndarray, hands2d: np.ndarray,
                  found: np.ndarray, use_hands: bool = True, face3d: np.ndarray | None = None) -> FitTargets:
    """Targets for model points ``point_names`` from (already swap-corrected) landmarks; shapes as in
    :class:`~gma.video.detect.Detections`. ``face3d`` None: no face directions (their weight is 0)."""
    t, p = len(found), len(point_names)
    uv = np.zeros((t, p, 2), np.float32)
    conf = np.zeros((t, p), np.float32)
    index = {n: i for i, n in enumerate(point_names)}
    for mp_i, name in enumerate(POSE_POINTS):
        if name is None:
            continue
        k = index[name]
        ok = found & np.isfinite(pose2d[:, mp_i, 0])
        uv[ok, k] = pose2d[ok, mp_i, :2]
        conf[ok, k] = POSE_WEIGHTS[mp_i] * np.clip(pose2d[ok, mp_i, 2], 0, 1)
    if use_hands:
        for side, h in (("L", 0), ("R", 1)):
            for j, name in enumerate(HAND_POINTS[side]):
                k = index[name]
                ok = found & (hands2d[:, h, j, 2] > 0)
                uv[ok, k] = hands2d[ok, h, j, :2]
                # Two detectors see the same wrist/knuckles; where both do, the hand model's is sharper.
                conf[ok, k] = HAND_WEIGHT
    ends = np.array(BONE_PAIRS)
    vis = np.minimum(pose2d[:, ends[:, 0], 2], pose2d[:, ends[:, 1], 2])
    dirs, conf3d = _directions(pose3d, ends, found, np.nan_to_num(np.clip(vis, 0, 1)))
    if face3d is None:
        face3d = np.full((t, len(FACE_POINTS), 3), np.nan, np.float32)
    face_dirs, face_conf = _directions(face3d, np.array(FACE_PAIRS), found, 1.0)
    dirs, conf3d = np.concatenate([dirs, face_dirs], 1), np.concatenate([conf3d, face_conf], 1)
    pairs = np.array([[index[POSE_POINTS[a]], index[POSE_POINTS[b]]] for a, b in BONE_PAIRS]
                     + [[index[FACE_POINTS[a]], index[FACE_POINTS[b]]] for a, b in FACE_PAIRS])
    pts = np.where(conf[..., None] > 0.3, uv, np.nan)
    lo, hi = np.nanmin(pts, axis=1, initial=np.inf), np.nanmax(pts, axis=1, initial=-np.inf)
    diag = np.linalg.norm(hi - lo, axis=-1)
    scale = np.where(np.isfinite(diag) & (diag > 1), diag, np.nan)
    fill = np.nanmedian(scale) if np.isfinite(scale).any() else 100.0
    scale = np.where(np.isfinite(scale), scale, fill)
    f32 = lambda a: torch.as_tensor(np.asarray(a, np.float32))  # noqa: E731
    return FitTargets(f32(uv), f32(conf), f32(dirs), f32(conf3d), torch.as_tensor(pairs),
                      f32(BONE_PAIR_WEIGHTS + FACE_PAIR_WEIGHTS), f32(scale), torch.as_tensor(found))


def _directions(points: np.ndarray, ends: np.ndarray, found: np.ndarray, conf) -> tuple[np.ndarray, np.ndarray]:
    """Unit directions [T, B, 3] from ``points`` [T, N, 3] between the pairs ``ends`` [B, 2], and their
    weights [T, B]: ``conf`` where the frame has a detection and both ends are known, else 0."""
    d = points[:, ends[:, 1]] - points[:, ends[:, 0]]
    norm = np.linalg.norm(d, axis=-1, keepdims=True)
    good = found[:, None] & np.isfinite(norm[..., 0]) & (norm[..., 0] > 1e-4)
    dirs = np.where(good[..., None], d / np.where(good[..., None], norm, 1), 0)
    return dirs, np.where(good, conf, 0.0)
