"""``gma import motion clip.mp4 motion.npz``: the motion of the person in a video as Anny poses — the
video import's detection and body fit (:mod:`gma.video.pipeline`) without masks, images or cameras as
output.

The fit poses the body in the camera's frame (x right, y down, z forward). A motion file is in Anny's
world (Z up, facing −Y), so the root is turned from one to the other — a person facing the camera faces
−Y — and then levelled so that the body's mean up direction over the clip is +Z (a tilted camera is
the usual cause of a lean; this assumes the person stands upright on average). Roots start at the
horizontal origin and, by default, a foot is put on the floor in every frame (``feet="frame"``: the fit's
depth noise makes the root bob by several centimetres otherwise; ``"clip"`` keeps the fitted heights
and only lifts the clip as a whole, for jumps).
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import torch

from gma.body import load_body
from gma.body.motion_files import place_on_floor, save_motion
from gma.body.motions import Motion
from gma.body.retarget import rotation_between
from gma.core.errors import InputError
from gma.core.outputs import prepare_output_file
from gma.video.frames import read_video
from gma.video.pipeline import (
    VideoImportConfig,
    checked_masks,
    detect_person,
    fit_detections,
    reusable_work,
    video_camera,
    work_dir,
)
from gma.video.report import reprojection_errors

__all__ = ["CAMERA_TO_ANNY", "estimate_motion", "upright_motion", "video_fps"]

# Camera axes (x right, y down, z forward) into Anny's world for a person facing the camera.
CAMERA_TO_ANNY = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def video_fps(path: str | os.PathLike, default: float = 30.0) -> float:
    """Frames per second the container declares (``default`` when it declares none)."""
    try:
        gen = imageio_ffmpeg.read_frames(str(path))
        meta = next(gen)
        gen.close()
    except (OSError, RuntimeError, StopIteration, ValueError):
        return default
    fps = float(meta.get("fps") or 0)
    return fps if np.isfinite(fps) and 0 < fps < 1000 else default


def upright_motion(pose: np.ndarray) -> np.ndarray:
    """[T, J, 4, 4] fitted poses in the camera's frame → Anny's world, levelled, starting at the origin
    (heights are settled by :func:`place_on_floor`)."""
    pose = pose.astype(np.float64).copy()
    rot, trans = CAMERA_TO_ANNY @ pose[:, 0, :3, :3], pose[:, 0, :3, 3] @ CAMERA_TO_ANNY.T
    up = rot[:, :, 2].mean(0)  # the root's up axis, averaged over the clip
    level = rotation_between(up, np.array([0.0, 0.0, 1.0]))
    pose[:, 0, :3, :3], pose[:, 0, :3, 3] = level @ rot, trans @ level.T
    pose[:, 0, :2, 3] -= pose[0, 0, :2, 3]
    return pose


def estimate_motion(src: str | os.PathLike, out: str | os.PathLike, *, config: VideoImportConfig | None = None,
                    overwrite: bool = False, progress: bool = True, anny=None,
                    feet: str = "frame") -> tuple[Motion, dict]:
    """Fit Anny to the person in video ``src`` and write the motion to ``out`` (an Anny ``body.npz``
    with ``fps``). Returns (motion, report). Detections and the fit are kept in ``OUT.work`` as by
    ``gma import video``, so a second run (or ``gma import video`` of the same clip's settings) reuses them."""
    cfg = config or VideoImportConfig()
    src, out = Path(src), Path(out)
    if out.suffix.lower() != ".npz":
        raise InputError(f"{out}: a motion is written as .npz")
    if feet not in ("frame", "clip"):
        raise InputError(f"feet must be 'frame' or 'clip', got {feet!r}")
    prepare_output_file(out, overwrite)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    frames, idx = read_video(src, cfg.start, cfg.end, cfg.skip, cfg.max_frames, max_bytes=cfg.max_decoded_bytes)
    timings["decode"] = time.perf_counter() - t0
    frames, K, _ = video_camera(frames, cfg)
    work = work_dir(out)
    with reusable_work(work):
        det, reused = detect_person(src, frames, work, progress, timings, cfg.tracking)
        # The body fit's silhouette term (body shape) sees the masks checked against the background.
        masks, mask_check = checked_masks(frames, det.masks, cfg, progress, timings)
        pose, phenotype, info = fit_detections(det, masks, K, cfg, work, anny, progress, timings)
    body = anny if anny is not None else load_body("anny")
    shape = torch.from_numpy(np.asarray(phenotype, np.float32))
    posed = place_on_floor(body, torch.from_numpy(upright_motion(pose)).float(), shape, per_frame=feet == "frame")
    fps = video_fps(src) / cfg.skip
    motion = Motion(src.stem, posed, torch.zeros(len(posed), 52), shape, fps)
    save_motion(out, motion)
    err = reprojection_errors(info["uv"], info["target_uv"], info["conf"])
    report = {"video": str(src), "frames_used": len(frames), "frames_detected": int(det.found.sum()),
              "frames_interpolated": int((~det.found).sum()), "frames_detect_reused": int(reused),
              "fps": fps, "fit_resumed_from_cache": bool(info["resumed_fit"]), "mask_check": mask_check,
              "reprojection_error_px_mean": float(np.nanmean(err)) if np.isfinite(err).any() else None,
              "seconds": {k: round(v, 3) for k, v in timings.items()}}
    return motion, report
