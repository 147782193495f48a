"""``gma import video clip.mp4 OUT``: from a raw video to a sequence (docs/design.md "Sequence") for
the default Anny body — masks and landmarks (MediaPipe), a static pinhole camera, a body fit, and a
report with a contact sheet.

Work that takes time is kept in ``OUT.work/`` (next to OUT, not inside it, so the sequence stays
clean and OUT can be written atomically): per-frame detections ``detect/000000.npz`` and the fit
``fit_<key>.npz``, keyed by the frames' pixels and the settings, so a second run — after a crash, or
with ``--force`` to rewrite OUT — reuses them. Delete ``OUT.work/`` to start over.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gma.body import load_body
from gma.body.params import SequenceBody
from gma.body.params import load_body as load_body_params
from gma.core.atomic import atomic_write_json, atomic_write_npz
from gma.core.errors import GmaError, InputError
from gma.data.importers._common import mask_from_array, write_imported
from gma.data.importers.video import count_frames
from gma.data.sequence import IMAGE_SUFFIXES, Sequence, prepare_sequence_output
from gma.video.camera import CameraIntrinsics, Undistortion, intrinsics, static_camera
from gma.video.detect import detect_frames
from gma.video.fit import FitConfig, fit_body
from gma.video.frames import memory_budget, read_video
from gma.video.matte import refine_masks
from gma.video.report import contact_sheet, mask_iou, overlay, project_vertices, reprojection_errors, silhouette
from gma.video.rig import AnnyRig
from gma.video.smooth import smooth_landmarks
from gma.video.swaps import LIMB_PAIRS, apply_limb_swaps, apply_swaps, resolve_limb_swaps, resolve_swaps
from gma.video.targets import build_targets

__all__ = ["VideoImportConfig", "estimate_sequence", "work_dir"]

REPORT_NAME = "video_report.json"
SHEET_NAME = "video_contact_sheet.png"


@dataclass
class VideoImportConfig:
    """Settings of a video import without user-supplied body parameters."""

    focal: float | None = None  # focal length in pixels (default: the image's longer side)
    camera: CameraIntrinsics | None = None  # the user's calibration (``--camera``); excludes ``focal``
    start: int = 0  # first video frame
    end: int | None = None  # stop before this frame
    skip: int = 1  # keep every N-th frame
    max_frames: int = 3000  # refuse longer selections (memory: frames are held decoded)
    max_decoded_bytes: int | None = field(default_factory=memory_budget)  # of decoded frames (gma.video.frames)
    sheet_frames: int = 12  # overlays on the contact sheet
    check_masks: bool = True  # MediaPipe's masks checked against the background plate (gma.video.matte)
    tracking: bool = True  # MediaPipe tracks the person from frame to frame (else: each frame on its own)
    fit: FitConfig = field(default_factory=FitConfig)


def video_camera(frames: np.ndarray, cfg: VideoImportConfig) -> tuple[np.ndarray, np.ndarray, Undistortion | None]:
    """The camera of ``frames`` [T, H, W, 3]: (frames, undistorted when the camera file gives distortion,
    K [3, 3] in GMA's pixel convention, the :class:`Undistortion` used or None). A camera file that does
    not fit the frames, or together with ``focal``, is an :class:`InputError` naming it."""
    H, W = frames.shape[1:3]
    if cfg.camera is None:
        return frames, intrinsics(W, H, cfg.focal), None
    if cfg.focal is not None:
        raise InputError(f"{cfg.camera.source}: give the focal length either in the camera file or with --focal, "
                         "not both")
    cfg.camera.check_frame(W, H)
    if not cfg.camera.distorted:
        return frames, cfg.camera.K(), None
    undistort = Undistortion(cfg.camera, W, H)
    return np.stack([undistort(f) for f in frames]), cfg.camera.K(), undistort


def work_dir(out: str | os.PathLike) -> Path:
    """Where resumable work for ``out`` is kept."""
    out = Path(out)
    return out.parent / (out.name + ".work")


def _masks_from_dir(mask_dir: Path, idx: list[int], n: int, shape: tuple[int, int]) -> np.ndarray:
    from gma.core.images import read_image

    files = sorted(p for p in Path(mask_dir).glob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if len(files) != n:
        raise ValueError(f"{mask_dir}: {len(files)} mask images for {n} video frames")
    out = []
    for i in idx:
        m = mask_from_array(read_image(files[i]), files[i])
        if m.shape != shape:
            raise ValueError(f"{files[i]}: mask is {m.shape[1]}x{m.shape[0]}, video is {shape[1]}x{shape[0]}")
        out.append(m)
    return np.stack(out)


# Bumped when the body fit changes in a way its settings do not show (2: per-pair weights of the 3D
# directions; 3: limb swaps resolved and landmarks smoothed before the fit; 4: the face mesh's eye
# line), so that OUT.work/ never hands back a fit the current code would not make.
FIT_CACHE_VERSION = 4


def _fit_key(det, K: np.ndarray, cfg: FitConfig) -> str:
    h = hashlib.sha1(f"fit v{FIT_CACHE_VERSION}".encode())
    for a in (det.pose2d, det.pose3d, det.hands2d, det.found, det.face, det.face3d, K):
        h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps(dataclasses.asdict(cfg), sort_keys=True).encode())
    return h.hexdigest()[:16]


def estimate_sequence(src: str | os.PathLike, out: str | os.PathLike, *, config: VideoImportConfig | None = None,
                      mask_dir: str | os.PathLike | None = None, body: str | os.PathLike | None = None,
                      downscale: int = 1, overwrite: bool = False, progress: bool = True,
                      anny=None) -> tuple[Sequence, dict]:
    """Turn video ``src`` into a sequence at ``out``. Returns (sequence, report dict).

    ``mask_dir``: the user's masks (one image per video frame) instead of MediaPipe's. ``body``: the
    user's ``body.npz`` (Anny, all or the selected frames) instead of the fit. ``anny``: an
    ``AnnyBody`` to reuse (tests create one per session).
    """

    cfg = config or VideoImportConfig()
    src, out = Path(src), Path(out)
    prepare_sequence_output(out, overwrite)
    timings: dict[str, float] = {}
    t0 = time.perf_counter()
    decoded: dict = {}
    frames, idx = read_video(src, cfg.start, cfg.end, cfg.skip, cfg.max_frames, decoded, cfg.max_decoded_bytes)
    n_src = decoded.get("frames_total")  # None unless every frame was read to the end (then counted if needed)
    timings["decode"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    frames, K, undistort = video_camera(frames, cfg)
    timings["undistort"] = time.perf_counter() - t0
    work = work_dir(out)
    with reusable_work(work):
        return _estimate(src, out, frames, K, undistort, idx, n_src, work, cfg, mask_dir, body, downscale,
                         overwrite, progress, anny, timings, decoded.get("hdr"))


@contextlib.contextmanager
def reusable_work(work: Path) -> Iterator[Path]:
    """Around work that fills ``work`` (``OUT.work``): on a failure, a folder this run created is kept only
    when it holds what a next run reuses (detections, a body fit), and the error says so; otherwise it is
    removed, so a failed import leaves nothing behind."""
    existed = work.exists()
    try:
        yield work
    except (GmaError, ValueError) as exc:
        if not existed and (not any(work.rglob("*.npz")) or "no person detected" in str(exc)):
            shutil.rmtree(work, ignore_errors=True)
            raise
        raise type(exc)(f"{exc} (the detections and fits done so far are kept in {work}; the next run reuses "
                        "them, delete it to start over)") from None


def detect_person(src: Path, frames: np.ndarray, work: Path, progress: bool, timings: dict, tracking: bool = True):
    """MediaPipe detections of ``frames`` [T, H, W, 3] (cached in ``work/detect``): (detections, frames
    reused from the cache). No person in any frame is an :class:`InputError` naming ``src``."""
    t0 = time.perf_counter()
    det, reused = detect_frames(frames, work / "detect", progress=progress, tracking=tracking)
    timings["detect"] = time.perf_counter() - t0
    if not det.found.any():
        raise InputError(f"{src}: no person detected in any of the {len(frames)} frames")
    return det, reused


def checked_masks(frames: np.ndarray, masks: np.ndarray, cfg: VideoImportConfig, progress: bool,
                  timings: dict) -> tuple[np.ndarray, dict]:
    """MediaPipe's ``masks`` checked against the clip's background (:mod:`gma.video.matte`) when
    ``cfg.check_masks``, and the report's ``mask_check`` entry; the time goes into ``timings["masks"]``."""
    if not cfg.check_masks:
        return masks, {"applied": False, "reason": "--no-mask-check"}
    t0 = time.perf_counter()
    checked, report = refine_masks(frames, masks, progress=progress)
    timings["masks"] = time.perf_counter() - t0
    return checked, report


def _estimate(src, out, frames, K, undistort, idx, n_src, work, cfg, mask_dir, body, downscale, overwrite,
              progress, anny, timings, hdr):
    T, H, W = frames.shape[:3]
    # The user's inputs are read (and checked) before the minutes of detection.
    user_body = _user_body(body, idx, src) if body is not None else None
    if mask_dir is not None:
        total = n_src if n_src is not None else _count(src)
        masks = _masks_from_dir(Path(mask_dir), idx, total, (H, W))
        if undistort is not None:  # the user's masks are of the distorted frames
            masks = np.stack([undistort(m) for m in masks])
        mask_check = {"applied": False, "reason": "the user's masks"}
    det, reused = detect_person(src, frames, work, progress, timings, cfg.tracking)
    if mask_dir is None:
        masks, mask_check = checked_masks(frames, det.masks, cfg, progress, timings)

    if user_body is not None:
        (pose, phenotype), fit_info = user_body, {}
    else:
        pose, phenotype, fit_info = fit_detections(det, masks, K, cfg, work, anny, progress, timings)
    centre = np.median(pose[:, 0, :3, 3], axis=0)
    pose = pose.copy()
    pose[:, 0, :3, 3] -= centre  # world origin at the person's median root position
    cams = static_camera(W, H, K, -centre)
    seq_body = SequenceBody("anny", {"pose": pose.astype(np.float32), "phenotype": phenotype.astype(np.float32)})

    t0 = time.perf_counter()
    report, sheet = _report(src, frames, masks, det, idx, reused, pose, phenotype, cams, fit_info, cfg, anny)
    timings["report"] = time.perf_counter() - t0
    report["mask_check"] = mask_check
    report["hdr"] = hdr  # "HLG" / "PQ": the frames were tone-mapped to SDR; None: an SDR video
    report["seconds"] = {k: round(v, 3) for k, v in timings.items()}
    report["seconds_per_frame"] = {k: round(v / T, 4) for k, v in timings.items()}

    def extra(writer) -> None:
        import imageio.v3 as iio

        atomic_write_json(writer.path(REPORT_NAME), report)
        iio.imwrite(writer.path(SHEET_NAME), sheet)

    t0 = time.perf_counter()
    pairs = ((frames[t], masks[t]) for t in range(T))
    seq = write_imported(out, pairs, T, cams, seq_body, None, downscale, overwrite, "write", extra)
    report["seconds"]["write"] = round(time.perf_counter() - t0, 3)
    return seq, report


def _camera_report(K: np.ndarray, cfg: VideoImportConfig) -> dict:
    """The camera as the report states it: K in GMA's convention at the video's size, and where it came from."""
    out = {"focal_px": float(K[0, 0]), "focal_px_y": float(K[1, 1]),
           "principal_point": [float(K[0, 2]), float(K[1, 2])]}
    if cfg.camera is not None:
        out["source"] = f"camera file {cfg.camera.source}"
        out["distortion_k1_k2_p1_p2_k3"] = list(cfg.camera.dist)
        out["undistorted"] = cfg.camera.distorted
    else:
        out["source"] = "--focal" if cfg.focal is not None else "default (longer image side, centred)"
    return out


def _count(src: Path) -> int:
    return count_frames(src)


def _user_body(body, idx: list[int], src: Path) -> tuple[np.ndarray, np.ndarray]:
    params = load_body_params(body)
    if params.model != "anny":
        raise ValueError(f"{body}: the video pipeline writes Anny sequences; this file holds {params.model!r} "
                         "(give --camera and a mask source to import it as is)")
    n_sel = len(idx)
    if params.num_frames == n_sel:
        sel = params
    elif params.num_frames > idx[-1]:
        sel = params.subset(idx)
    else:
        raise ValueError(f"{body}: {params.num_frames} frames of body parameters for {n_sel} selected frames of {src}")
    return sel.arrays["pose"], np.asarray(sel.arrays["phenotype"])


def fit_detections(det, masks, K, cfg: VideoImportConfig, work: Path, anny, progress: bool, timings: dict):
    """Anny fitted to detections ``det`` and ``masks`` [T, H, W] for camera ``K``: (pose [T, J, 4, 4] in
    the camera's frame, phenotype [6], fit info), cached in ``work`` by its inputs and settings."""
    t0 = time.perf_counter()
    p2, p3, h2, swaps, limb_swaps = clean_landmarks(det, cfg.fit.smooth_frames)
    key = _fit_key(det, K, cfg.fit) + hashlib.sha1(np.ascontiguousarray(masks).tobytes()).hexdigest()[:8]
    cache = work / f"fit_{key}.npz"
    if anny is None:
        anny = load_body("anny")
    rig = AnnyRig(anny, fit_hands=cfg.fit.fit_hands)
    # A frame whose whole body was swapped shows the person's back: its face mesh (if any) is not trusted.
    face3d = np.where(swaps[:, None, None], np.nan, det.face3d)
    tg = build_targets(rig.point_names, p2, p3, h2, det.found, use_hands=cfg.fit.fit_hands, face3d=face3d)
    timings["prepare"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if cache.is_file():
        with np.load(cache, allow_pickle=False) as z:
            pose, phenotype, uv = z["pose"], z["phenotype"], z["uv"]
        resumed = True
    else:
        res = fit_body(rig, tg, p3, K, masks, cfg.fit, progress=progress)
        pose, phenotype, uv = res.pose, res.phenotype, res.uv
        atomic_write_npz(cache, pose=pose, phenotype=phenotype, uv=uv)
        resumed = False
    timings["fit"] = time.perf_counter() - t0
    # The report scores the fit against the landmarks as detected (swaps undone), not the smoothed ones.
    seen = build_targets(rig.point_names, *clean_landmarks(det, 0)[:3], det.found, use_hands=cfg.fit.fit_hands)
    info = {"uv": uv, "target_uv": seen.uv.numpy(), "conf": seen.conf.numpy(), "swapped": swaps,
            "limbs_swapped": limb_swaps, "resumed_fit": resumed, "points": rig.point_names}
    return pose, phenotype, info


def clean_landmarks(det, smooth_frames: int):
    """The detections' landmarks made ready for the fit: left/right swaps of the whole body (back views)
    and of single limb pairs (profiles) undone, then the tracks smoothed over ``smooth_frames`` frames
    either side (0: not). Returns (pose2d, pose3d, hands2d, body swaps [T] bool, {limb: [T] bool})."""
    swaps = resolve_swaps(det.pose3d, det.found, det.face)
    p2, p3, h2 = apply_swaps(det.pose2d, det.pose3d, det.hands2d, swaps)
    limb_swaps = {limb: resolve_limb_swaps(p2, p3, det.found, limb) for limb in LIMB_PAIRS}
    p2, p3, h2 = apply_limb_swaps(p2, p3, h2, limb_swaps)
    p2, p3, h2 = smooth_landmarks(p2, p3, h2, det.found, smooth_frames)
    return p2, p3, h2, swaps, limb_swaps


def _report(src, frames, masks, det, idx, reused, pose, phenotype, cams, fit_info, cfg,
            anny) -> tuple[dict, np.ndarray]:
    import torch

    if anny is None:
        anny = load_body("anny")
    T, H, W = frames.shape[:3]
    K, w2c = cams.frame(0)
    faces = anny.faces.numpy()
    with torch.no_grad():
        verts = anny.pose({"pose": torch.from_numpy(pose).float(),
                           "shape": torch.from_numpy(np.asarray(phenotype)).float()}).vertices.numpy()
    ious = []
    for t in range(T):
        uv, _ = project_vertices(verts[t], K, w2c)
        ious.append(mask_iou(silhouette(uv, faces, W, H), masks[t] > 0.5))
    ious = np.array(ious)
    sheet_idx = np.unique(np.linspace(0, T - 1, min(cfg.sheet_frames, T)).round().astype(int))
    tiles = []
    for t in sheet_idx:
        uv, depth = project_vertices(verts[t], K, w2c)
        pts = det.pose2d[t, :, :2] if det.found[t] else None
        tiles.append(overlay(frames[t], uv, depth, faces, pts))
    sheet = contact_sheet(tiles, columns=min(4, len(tiles)), tile_width=min(256, W))
    report = {
        "video": str(src),
        "frames_used": T,
        "source_frames": [int(i) for i in idx],
        "frames_detected": int(det.found.sum()),
        "detection_rate": round(det.detection_rate, 4),
        "frames_interpolated": int((~det.found).sum()),
        "frames_with_hands": int((det.hands2d[:, :, 0, 2] > 0).any(1).sum()),
        "frames_detect_reused": int(reused),
        "mask_iou_mean": round(float(ious.mean()), 4),
        "mask_iou_per_frame": [round(float(x), 4) for x in ious],
        "camera": _camera_report(K, cfg),
        "phenotype": [round(float(x), 4) for x in phenotype],
        "phenotype_named": {name: round(float(x), 4) for name, x in
                            zip(anny.param_spaces["shape"].labels, phenotype, strict=True)},
        "contact_sheet_frames": [int(t) for t in sheet_idx],
    }
    if fit_info:
        err = reprojection_errors(fit_info["uv"], fit_info["target_uv"], fit_info["conf"])
        report.update({
            "reprojection_error_px_mean": round(float(np.nanmean(err)), 3) if np.isfinite(err).any() else None,
            "reprojection_error_px_per_frame": [None if not np.isfinite(e) else round(float(e), 3) for e in err],
            "frames_swapped_left_right": int(fit_info["swapped"].sum()),
            "frames_limbs_swapped": {k: int(v.sum()) for k, v in fit_info["limbs_swapped"].items()},
            "fit_resumed_from_cache": bool(fit_info["resumed_fit"]),
            "fit_config": dataclasses.asdict(cfg.fit),
        })
    return report, sheet
