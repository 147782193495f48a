"""Left/right swaps of landmark detectors in back views.

A single image of a person seen from behind projects exactly like the depth-mirrored person seen from
the front, and MediaPipe — trained mostly on frontal people — often picks the frontal reading: it then
labels the person's left side "right" and mirrors the depth of its 3D landmarks. Per frame there are
two readings: as detected (h0), or with left/right labels exchanged and the 3D depth mirrored (h1).

Which one holds is decided over the whole clip by dynamic programming on the body's facing angle
(yaw) from the 3D landmarks: h1 turns a yaw θ into π − θ. The cost prefers a yaw that changes at a
steady rate (a person turning keeps turning; a second difference is cheap only then), h0 over h1 by a
small margin, a yaw facing the camera whenever MediaPipe found a face (no face is seen from behind),
and — in clips where the face detector works at this resolution (faces in at least ``MIN_FACE_SHARE``
of the frames) — a yaw facing away when no face is found.

A second kind of swap keeps the torso and exchanges one pair of limbs: in a profile view the two arms
(or legs) overlap, and the detector may give the near one the far one's label for a few frames. The
torso's yaw cannot see that (its shoulders and hips are labelled right), so :func:`resolve_limb_swaps`
decides per limb pair, again over the whole clip by dynamic programming: a limb's landmarks move little
from one frame to the next, in the image and in the 3D landmarks (where the near and far limb of a
profile lie a shoulder's width apart in depth, though they overlap in the image), and the first joint of
a limb (elbow, knee) lies nearer its own shoulder or hip than the other side's where the view shows
them apart.
"""

from __future__ import annotations

import numpy as np

from gma.video.landmarks import POSE_FLIP

__all__ = ["LIMB_PAIRS", "apply_limb_swaps", "apply_swaps", "facing_yaw", "resolve_limb_swaps", "resolve_swaps"]

_L_SH, _R_SH, _L_HIP, _R_HIP = 11, 12, 23, 24
# Share of frames with a face from which "no face" counts as evidence of a back view. A turning person
# faces the camera in about half the frames (the iPER turn: faces in 23 of 53); a detector that finds
# one face in 24 frames (a 256 px synthetic turn) is not working, and trusting its silence there read
# the last five frames of the turn as back views: mirrored bodies, joints 13-48 px off.
MIN_FACE_SHARE = 0.2


def facing_yaw(pose3d: np.ndarray) -> np.ndarray:
    """Facing angle [T] (radians) from MediaPipe world landmarks [T, 33, 3] (camera axes): 0 = facing
    the camera, ±π = facing away, positive = turned towards the camera's +x. NaN where missing."""
    lat = (pose3d[:, _L_SH] - pose3d[:, _R_SH]) + (pose3d[:, _L_HIP] - pose3d[:, _R_HIP])   # towards the person's left
    up = (pose3d[:, _L_SH] + pose3d[:, _R_SH] - pose3d[:, _L_HIP] - pose3d[:, _R_HIP])       # hips → shoulders
    fwd = np.cross(lat, up)  # left × up = forward (Anny: +X × +Z = −Y, the way the body faces)
    return np.arctan2(fwd[:, 0], -fwd[:, 2])


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def resolve_swaps(pose3d: np.ndarray, found: np.ndarray, face: np.ndarray, swap_cost: float = 0.3,
                  face_cost: float = 4.0, no_face_cost: float = 1.0, accel_weight: float = 4.0) -> np.ndarray:
    """Per-frame decision [T] bool: True where the detection should be read as swapped (h1).

    Frames without a detection are False (nothing to swap). Viterbi over pairs of consecutive states,
    so that the cost can use second differences of the yaw.
    """
    t_all = np.nonzero(found)[0]
    out = np.zeros(len(found), bool)
    if len(t_all) == 0:
        return out
    y0 = facing_yaw(pose3d[t_all])
    yaws = np.stack([y0, _wrap(np.pi - y0)], 1)                        # [N, 2] per hypothesis
    unary = np.zeros((len(t_all), 2))
    unary[:, 1] += swap_cost
    has_face = face[t_all]
    unary[has_face] += face_cost * (np.abs(yaws[has_face]) > np.pi / 2)
    if has_face.mean() >= MIN_FACE_SHARE:
        unary[~has_face] += no_face_cost * (np.abs(yaws[~has_face]) < np.pi / 3)
    n = len(t_all)
    if n == 1:
        out[t_all[0]] = bool(np.argmin(unary[0]))
        return out
    # state k = (s_prev, s_cur) as 2 * s_prev + s_cur
    cost = np.full(4, np.inf)
    for sp in range(2):
        for sc in range(2):
            cost[2 * sp + sc] = unary[0, sp] + unary[1, sc]
    back = np.zeros((n, 4), np.int64)
    for i in range(2, n):
        new = np.full(4, np.inf)
        for sp in range(2):
            for sc in range(2):
                best, arg = np.inf, 0
                for spp in range(2):
                    k = 2 * spp + sp
                    acc = _wrap(yaws[i, sc] - yaws[i - 1, sp]) - _wrap(yaws[i - 1, sp] - yaws[i - 2, spp])
                    c = cost[k] + accel_weight * float(acc) ** 2
                    if c < best:
                        best, arg = c, k
                new[2 * sp + sc] = best + unary[i, sc]
                back[i, 2 * sp + sc] = arg
        cost = new
    k = int(np.argmin(cost))
    states = np.zeros(n, np.int64)
    states[n - 1], states[n - 2] = k % 2, k // 2
    for i in range(n - 1, 1, -1):
        k = back[i, k]
        states[i - 2] = k // 2
    out[t_all] = states.astype(bool)
    return out


def apply_swaps(pose2d: np.ndarray, pose3d: np.ndarray, hands2d: np.ndarray, swap: np.ndarray):
    """Landmarks with left/right exchanged (and 3D depth mirrored) in frames where ``swap`` [T] is True.
    Shapes as in :class:`~gma.video.detect.Detections`; returns new arrays."""
    p2, p3, h2 = pose2d.copy(), pose3d.copy(), hands2d.copy()
    p2[swap] = pose2d[swap][:, POSE_FLIP]
    p3[swap] = pose3d[swap][:, POSE_FLIP]
    p3[swap, :, 2] *= -1
    h2[swap] = hands2d[swap][:, ::-1]
    return p2, p3, h2


# Limb pairs a detector may swap on their own: MediaPipe pose indices of the left limb from its first
# joint outwards (the right limb's are their POSE_FLIP), and the torso landmark the limb hangs from.
LIMB_PAIRS = {"arms": ((13, 15, 17, 19, 21), 11), "legs": ((25, 27, 29, 31), 23)}


def _limb_points(pose2d: np.ndarray, pose3d: np.ndarray, left: tuple[int, ...]):
    """Image and 3D points of a limb pair under both labellings: [N, 2 (kept, exchanged), 2 sides, L, 2|3]."""
    right = tuple(int(POSE_FLIP[i]) for i in left)
    uv = np.stack([pose2d[:, left, :2], pose2d[:, right, :2]], 1)
    xyz = np.stack([pose3d[:, left], pose3d[:, right]], 1)
    return np.stack([uv, uv[:, ::-1]], 1), np.stack([xyz, xyz[:, ::-1]], 1)


def _sizes(pose2d: np.ndarray, pose3d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Person size per frame [N]: the landmarks' bounding-box diagonal in pixels and in metres."""
    def diag(a):
        d = np.linalg.norm(np.nanmax(a, 1) - np.nanmin(a, 1), axis=-1)
        return np.where(np.isfinite(d) & (d > 1e-6), d, np.nanmedian(d) if np.isfinite(d).any() else 1.0)
    return diag(pose2d[..., :2]), diag(pose3d)


def resolve_limb_swaps(pose2d: np.ndarray, pose3d: np.ndarray, found: np.ndarray, limb: str,
                       swap_cost: float = 0.05, attach_weight: float = 1.0) -> np.ndarray:
    """Per-frame decision [T] bool: True where the left and right ``limb`` (a key of ``LIMB_PAIRS``) should
    be exchanged. Landmarks as in :class:`~gma.video.detect.Detections`, torso labels already right
    (after :func:`apply_swaps`).

    Costs, in units of the person's size: moving the limb's landmarks between consecutive detected
    frames (image and 3D each), ``swap_cost`` per exchanged frame, and ``attach_weight`` × how much
    farther the limbs' first joints lie from their own torso landmarks than in the other labelling.
    """
    left, root = LIMB_PAIRS[limb]
    out = np.zeros(len(found), bool)
    t_all = np.nonzero(found)[0]
    if len(t_all) == 0:
        return out
    p2, p3 = np.nan_to_num(pose2d[t_all]), np.nan_to_num(pose3d[t_all])
    uv, xyz = _limb_points(p2, p3, left)                                       # [N, 2, 2, L, .]
    size_px, size_m = _sizes(p2, p3)
    roots = np.stack([p2[:, root, :2], p2[:, int(POSE_FLIP[root]), :2]], 1)    # [N, 2 sides, 2]
    attach = np.linalg.norm(uv[:, :, :, 0] - roots[:, None], axis=-1).sum(-1)  # [N, 2 labellings]
    unary = attach_weight * (attach - attach.min(1, keepdims=True)) / size_px[:, None]
    unary[:, 1] += swap_cost
    # move[i, a, b]: landmarks' travel from frame i-1 labelled a to frame i labelled b
    move = (np.linalg.norm(uv[1:, None] - uv[:-1, :, None], axis=-1).mean((-1, -2)) / size_px[1:, None, None]
            + np.linalg.norm(xyz[1:, None] - xyz[:-1, :, None], axis=-1).mean((-1, -2)) / size_m[1:, None, None])
    cost, back = unary[0].copy(), np.zeros((len(t_all), 2), np.int64)
    for i in range(1, len(t_all)):
        total = cost[:, None] + move[i - 1]                                    # [prev, cur]
        back[i] = total.argmin(0)
        cost = total.min(0) + unary[i]
    state = int(cost.argmin())
    for i in range(len(t_all) - 1, -1, -1):
        out[t_all[i]] = bool(state)
        state = back[i, state]
    return out


def apply_limb_swaps(pose2d: np.ndarray, pose3d: np.ndarray, hands2d: np.ndarray, swap: dict[str, np.ndarray]):
    """Landmarks with the left and right limbs of ``swap`` ({limb: [T] bool}) exchanged in the frames
    marked; a swapped arm takes its hand's landmarks along. Returns new arrays."""
    p2, p3, h2 = pose2d.copy(), pose3d.copy(), hands2d.copy()
    for limb, frames in swap.items():
        left = list(LIMB_PAIRS[limb][0])
        both = left + [int(POSE_FLIP[i]) for i in left]
        other = [int(POSE_FLIP[i]) for i in left] + left
        for a in (p2, p3):
            a[np.ix_(frames, both)] = a[np.ix_(frames, other)]
        if limb == "arms":
            h2[frames] = h2[frames][:, ::-1]
    return p2, p3, h2
