"""Motion files as Anny pose sequences: BVH (CMU-style), AMASS / SMPL(-H/-X) ``.npz`` (``poses``,
``trans``, ``mocap_framerate``) retargeted through :mod:`gma.body.retarget`, and Anny motions (a
sequence's ``body.npz`` or what ``gma import motion`` writes).

Root motion: the Anny root follows the source's root (hips / pelvis) scaled by the ratio of leg lengths
(so that steps cover the ground Anny's legs can cover and planted feet do not slide), starts at the
origin horizontally, and is lifted so that over the clip the lowest foot joint reaches the height it has
in Anny's rest pose (feet on the floor, never below it).
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import roma
import torch

from gma.body.motions import Motion, axis_angle_to_matrix, load_anny_motion
from gma.body.params import SequenceBody, save_body
from gma.body.registry import load_body
from gma.body.retarget import (
    SMPL_AXES,
    SMPLX_JOINTS,
    SMPLX_PARENTS,
    RetargetRig,
    axes_from_skeleton,
    rest_heads,
    smplx_rig,
)
from gma.core.errors import InputError, MissingFileError

__all__ = ["MOTION_SUFFIXES", "Bvh", "load_motion_file", "parse_bvh", "place_on_floor", "resample", "save_motion"]

MOTION_SUFFIXES = (".bvh", ".npz")
# Longest motion read (frames): far above a real clip (an hour at 120 fps), below what exhausts memory.
MAX_MOTION_FRAMES = 432_000
_FEET = ("foot.L", "foot.R", "toe3-1.L", "toe3-1.R")


# -- BVH -------------------------------------------------------------------------------------------------
class Bvh:
    """A parsed BVH: joint ``names``, ``parents`` [S] (−1 root), rest ``offsets`` [S, 3], per-joint
    ``channels`` (names, in file order) and ``channel_start`` [S], ``motion`` [T, C], ``frame_time`` (s)."""

    def __init__(self, names, parents, offsets, channels, motion, frame_time):
        self.names, self.parents = list(names), np.asarray(parents, np.int64)
        self.offsets, self.channels = np.asarray(offsets, np.float64), channels
        self.channel_start = np.cumsum([0] + [len(c) for c in channels])[:-1]
        self.motion, self.frame_time = motion, frame_time

    def rest_positions(self) -> np.ndarray:
        """[S, 3] joint positions at rest (source units and axes)."""
        pos = np.zeros_like(self.offsets)
        for j, p in enumerate(self.parents):
            pos[j] = self.offsets[j] + (pos[p] if p >= 0 else 0.0)
        return pos

    def forward_kinematics(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations [T, S, 3, 3] (from rest) and positions [T, S, 3] of every joint and frame."""
        t, s = len(self.motion), len(self.names)
        local = np.tile(np.eye(3), (t, s, 1, 1))
        trans = np.tile(self.offsets, (t, 1, 1))
        for j, chans in enumerate(self.channels):
            for k, ch in enumerate(chans):
                v = self.motion[:, self.channel_start[j] + k]
                axis = "XYZ".index(ch[0].upper())
                if ch[1:].lower() == "position":
                    trans[:, j, axis] += v
                else:  # channels listed first apply outermost: R = R_1 · R_2 · R_3
                    local[:, j] = local[:, j] @ _axis_rotation(axis, np.radians(v))
        g = np.empty_like(local)
        pos = np.empty((t, s, 3))
        for j, p in enumerate(self.parents):  # parents come before children in a BVH
            if p < 0:
                g[:, j], pos[:, j] = local[:, j], trans[:, j]
            else:
                g[:, j] = g[:, p] @ local[:, j]
                pos[:, j] = pos[:, p] + np.einsum("tij,j->ti", g[:, p], self.offsets[j])
        return g, pos


def _axis_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    c, s = np.cos(angle), np.sin(angle)
    r = np.tile(np.eye(3), (len(angle), 1, 1))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    r[:, i, i], r[:, i, j], r[:, j, i], r[:, j, j] = c, -s, s, c
    return r


def parse_bvh(path: str | Path) -> Bvh:
    """Read a BVH file; errors are :class:`InputError` naming the file and line."""
    path = Path(path)
    tokens = path.read_text(errors="replace").split()
    names, parents, offsets, channels, stack, i = [], [], [], [], [], 0

    def need(cond: bool, what: str) -> None:
        if not cond:
            raise InputError(f"{path}: not a BVH file I can read ({what})")

    need(bool(tokens) and tokens[0] == "HIERARCHY", "no HIERARCHY section")
    i = 1
    last = -1
    try:
        while tokens[i] != "MOTION":
            tok = tokens[i]
            if tok in ("ROOT", "JOINT", "End"):
                is_end = tok == "End"
                name = (names[stack[-1]] + "_end") if is_end else tokens[i + 1]
                need(bool(stack) or tok == "ROOT", f"joint {name!r} outside ROOT")
                names.append(name)
                parents.append(stack[-1] if stack else -1)
                offsets.append([0.0, 0.0, 0.0])
                channels.append([])
                last = len(names) - 1
                i += 2
            elif tok == "{":
                stack.append(last)
                i += 1
            elif tok == "}":
                need(bool(stack), "unbalanced braces")
                stack.pop()
                i += 1
            elif tok == "OFFSET":
                offsets[last] = [float(v) for v in tokens[i + 1:i + 4]]
                i += 4
            elif tok == "CHANNELS":
                n = int(tokens[i + 1])
                channels[last] = tokens[i + 2:i + 2 + n]
                need(all(re.fullmatch(r"[XYZ](position|rotation)", c, re.I) for c in channels[last]),
                     f"unknown channels {channels[last]}")
                i += 2 + n
            else:
                need(False, f"unexpected token {tok!r}")
        need(tokens[i + 1] == "Frames:" and tokens[i + 3] == "Frame" and tokens[i + 4] == "Time:", "bad MOTION header")
        frames, frame_time = int(tokens[i + 2]), float(tokens[i + 5])
        values = np.asarray(tokens[i + 6:], np.float64)
    except (IndexError, ValueError) as exc:
        raise InputError(f"{path}: not a BVH file I can read ({type(exc).__name__}: {exc})") from None
    need(not stack, "unbalanced braces")
    need(0 < frames <= MAX_MOTION_FRAMES, f"{frames} frames")
    need(math.isfinite(frame_time) and frame_time > 0, f"frame time {frame_time}")
    need(np.isfinite(np.asarray(offsets, np.float64)).all(), "a non-finite OFFSET")
    width = sum(len(c) for c in channels)
    need(values.size == frames * width, f"{values.size} motion values for {frames} frames of {width} channels")
    need(np.isfinite(values).all(), "non-finite motion values")
    return Bvh(names, parents, offsets, channels, values.reshape(frames, width), frame_time)


def _bvh_motion(path: Path, body) -> tuple[np.ndarray, np.ndarray, float]:
    bvh = parse_bvh(path)
    index = {n: i for i, n in enumerate(bvh.names)}
    rest = bvh.rest_positions()

    def find(*names: str) -> int | None:
        return next((index[n] for n in names if n in index), None)

    hips = 0
    left, right = find("LeftUpLeg", "LeftHip", "lThigh", "LHip"), find("RightUpLeg", "RightHip", "rThigh", "RHip")
    top = find("Head", "head", "Neck", "neck")
    if left is None or right is None or top is None:
        raise InputError(f"{path}: BVH skeleton without recognisable hips and head (joints named like CMU's "
                         "LeftUpLeg, RightUpLeg, Head)")
    axes = axes_from_skeleton(rest[left] - rest[right], rest[top] - rest[hips])

    def rest_dir(joint: str, child: str):
        return rest[index[child]] - rest[index[joint]]

    rig = RetargetRig.build(body, index, rest_dir, axes, axes, "bvh")
    g, pos = bvh.forward_kinematics()
    knee, ankle = find("LeftLeg", "LeftKnee", "lShin", "LKnee"), find("LeftFoot", "LeftAnkle", "lFoot", "LAnkle")
    src_leg = (np.linalg.norm(rest[knee] - rest[left]) + np.linalg.norm(rest[ankle] - rest[knee])
               if knee is not None and ankle is not None else None)
    root = pos[:, hips] @ axes.T
    return rig.local_deltas(g), _scale_root(body, root, src_leg), 1.0 / bvh.frame_time


# -- AMASS / SMPL-X --------------------------------------------------------------------------------------
def _amass_motion(path: Path, data: dict, body, up: str | None) -> tuple[np.ndarray, np.ndarray, float]:
    if "poses" in data:
        poses = np.asarray(data["poses"], np.float64)
    elif "root_orient" in data and "pose_body" in data:
        hands = data.get("pose_hand", np.zeros((len(data["root_orient"]), 90)))
        parts = [data["root_orient"], data["pose_body"], hands]
        poses = np.concatenate([np.asarray(p, np.float64) for p in parts], 1)
    else:
        raise InputError(f"{path}: an AMASS / SMPL-X motion needs 'poses' [T, 3·J] (or root_orient + pose_body)")
    if poses.ndim != 2 or poses.shape[1] not in (66, 72, 156, 165) or not 0 < len(poses) <= MAX_MOTION_FRAMES:
        raise InputError(f"{path}: 'poses' has shape {list(poses.shape)}; expected [T, 66|72|156|165] "
                         "(SMPL body, SMPL, SMPL+H, SMPL-X axis-angles)")
    t = len(poses)
    trans = np.asarray(data.get("trans", np.zeros((t, 3))), np.float64)
    if trans.shape != (t, 3):
        raise InputError(f"{path}: 'trans' has shape {list(trans.shape)}, expected [{t}, 3]")
    if not (np.isfinite(poses).all() and np.isfinite(trans).all()):
        raise InputError(f"{path}: non-finite values in 'poses' or 'trans'")
    fps_key = next((k for k in ("mocap_framerate", "mocap_frame_rate", "fps") if k in data), None)
    fps = float(data[fps_key]) if fps_key else 30.0
    if not (math.isfinite(fps) and fps > 0):
        raise InputError(f"{path}: frame rate {fps} is not a finite positive number")
    # Joint names of each layout: SMPL-X keeps jaw and eyes (22-24); SMPL+H goes straight to the hands.
    joints = {66: SMPLX_JOINTS[:22], 72: SMPLX_JOINTS[:22] + ("left_hand", "right_hand"),
              156: SMPLX_JOINTS[:22] + SMPLX_JOINTS[25:], 165: SMPLX_JOINTS}[poses.shape[1]]
    local = axis_angle_to_matrix(torch.from_numpy(poses.reshape(t, -1, 3))).numpy()
    parents = [SMPLX_PARENTS[SMPLX_JOINTS.index(n)] if n in SMPLX_JOINTS else (20 if n == "left_hand" else 21)
               for n in joints]
    index = {n: i for i, n in enumerate(joints)}
    g = np.empty_like(local)
    for j, p in enumerate(parents):
        g[:, j] = local[:, j] if p < 0 else g[:, index[SMPLX_JOINTS[p]]] @ local[:, j]
    # AMASS worlds are Z-up (the root orientation turns the Y-up model upright); other SMPL-X files are Y-up.
    up = up or ("z" if fps_key in ("mocap_framerate", "mocap_frame_rate") else "y")
    c_world = np.eye(3) if up == "z" else SMPL_AXES
    rig = smplx_rig(body, joints, c_world)
    return rig.local_deltas(g), _scale_root(body, trans @ c_world.T, None), fps


# -- shared ----------------------------------------------------------------------------------------------
def _scale_root(body, root: np.ndarray, src_leg: float | None) -> np.ndarray:
    """[T, 3] source root positions (Anny axes, source units) scaled to Anny's legs (``src_leg`` None:
    already metres on a human) and started at the horizontal origin. Height is settled later."""
    heads = rest_heads(body)
    b = body.bone_names
    anny_leg = (np.linalg.norm(heads[b.index("lowerleg01.L")] - heads[b.index("upperleg01.L")])
                + np.linalg.norm(heads[b.index("foot.L")] - heads[b.index("lowerleg01.L")]))
    scaled = root * (anny_leg / src_leg if src_leg else 1.0)
    scaled[:, :2] -= scaled[0, :2]
    return scaled


def place_on_floor(body, pose: torch.Tensor, shape: torch.Tensor, per_frame: bool = False) -> torch.Tensor:
    """``pose`` [T, J, 4, 4] with the root's height shifted so the lowest foot joint over the clip is at
    its rest-pose height — or, with ``per_frame``, in every frame (a foot always on the floor: right for
    walking, turning and dancing on the ground, wrong for jumps; it removes the bobbing that a monocular
    fit's depth noise gives the root)."""
    feet = [body.bone_names.index(n) for n in _FEET if n in body.bone_names]
    heads = torch.from_numpy(rest_heads(body, shape)).float()[feet]  # [F, 3]

    def lowest(p: torch.Tensor) -> torch.Tensor:
        with torch.no_grad():
            tr = body.bone_transforms({"pose": p, "shape": shape})[..., feet, :, :]  # [T, F, 4, 4]
        return ((tr[..., 2, :3] * heads).sum(-1) + tr[..., 2, 3]).amin(-1)  # [T]

    rest_low = lowest(body.canonical_pose()[None])[0]
    out = pose.clone()
    low = lowest(pose)
    out[:, 0, 2, 3] += rest_low - (low if per_frame else low.min())
    return out


def resample(pose: torch.Tensor, fps_in: float, fps_out: float) -> torch.Tensor:
    """[T, J, 4, 4] ``local-ref`` poses at ``fps_in`` → [T', J, 4, 4] at ``fps_out`` (same duration):
    rotations by normalised quaternion interpolation (frames are close, so this matches slerp to well
    under a degree), translations linearly."""
    if abs(fps_in - fps_out) < 1e-9 or len(pose) == 1:
        return pose
    t_out = torch.arange(int(np.floor((len(pose) - 1) * fps_out / fps_in + 1e-9)) + 1, dtype=torch.float64)
    x = t_out * fps_in / fps_out
    i0 = x.floor().long().clamp(max=len(pose) - 2)
    a = (x - i0).float()[:, None, None]
    q = roma.rotmat_to_unitquat(pose[..., :3, :3])  # [T, J, 4]
    q0, q1 = q[i0], q[i0 + 1]
    q1 = torch.where((q0 * q1).sum(-1, keepdim=True) < 0, -q1, q1)  # the short way round
    qi = torch.nn.functional.normalize(q0 * (1 - a) + q1 * a, dim=-1)
    out = torch.eye(4).repeat(len(t_out), pose.shape[1], 1, 1)
    out[..., :3, :3] = roma.unitquat_to_rotmat(qi)
    out[..., :3, 3] = pose[i0, :, :3, 3] * (1 - a) + pose[i0 + 1, :, :3, 3] * a
    return out


def load_motion_file(path: str | Path, body=None, fps: float | None = None, up: str | None = None) -> Motion:
    """A motion file as an Anny :class:`Motion` (resampled to ``fps`` when given): ``.bvh``, AMASS /
    SMPL-X ``.npz`` (``up`` "z" or "y" is the world's up axis, default z for AMASS, else y), or an Anny
    ``body.npz``. Errors are :class:`InputError` / :class:`MissingFileError` naming the file."""
    path = Path(path)
    if path.is_dir() and (path / "body.npz").is_file():
        path = path / "body.npz"
    if not path.is_file():
        raise MissingFileError(f"{path}: motion file not found")
    if path.suffix.lower() not in MOTION_SUFFIXES:
        raise InputError(f"{path}: unknown motion format {path.suffix!r}; expected .bvh or .npz "
                         "(AMASS / SMPL-X, or an Anny motion from gma import motion)")
    body = body or load_body("anny")
    if body.name != "anny":
        raise InputError(f"{path}: motions are retargeted to Anny, not {body.name!r}")
    shape = body.param_spaces["shape"].default_tensor()
    if path.suffix.lower() == ".npz":
        try:
            with np.load(path, allow_pickle=False) as f:
                data = {k: f[k] for k in f.files}
        except (ValueError, OSError) as exc:
            raise InputError(f"{path}: not a readable .npz ({exc})") from None
        if "model" in data or "pose" in data:
            src_fps = float(data["fps"]) if "fps" in data else 30.0
            try:
                motion = load_anny_motion(path, fps=src_fps)
            except ValueError as exc:
                raise InputError(str(exc)) from None
            if fps is not None:
                motion.pose = resample(motion.pose, src_fps, fps)
                motion.expression = motion.expression[_nearest(len(motion.expression), len(motion.pose))]
                motion.fps = fps
            return motion
        rot, root, src_fps = _amass_motion(path, data, body, up)
    else:
        rot, root, src_fps = _bvh_motion(path, body)
    pose = torch.eye(4).repeat(len(rot), len(body.bone_names), 1, 1)
    pose[..., :3, :3] = torch.from_numpy(rot).float()
    pose[:, 0, :3, 3] = torch.from_numpy(root).float()
    pose = place_on_floor(body, pose, shape)
    if fps is not None:
        pose = resample(pose, src_fps, fps)
    out_fps = fps or src_fps
    return Motion(path.stem, pose, torch.zeros(len(pose), 52), shape, out_fps)


def _nearest(n_in: int, n_out: int) -> np.ndarray:
    return np.minimum(np.round(np.linspace(0, n_in - 1, n_out)).astype(np.int64), n_in - 1)


def save_motion(path: str | Path, motion: Motion) -> None:
    """Write ``motion`` as an Anny ``body.npz`` with its ``fps`` (atomic; readable by
    :func:`load_motion_file` and as a sequence's body)."""
    save_body(path, SequenceBody("anny", {
        "pose": motion.pose.numpy().astype(np.float32), "phenotype": motion.shape.numpy().astype(np.float32),
        "facial_actions": motion.expression.clamp(0, 1).numpy().astype(np.float32),
        "fps": np.asarray(motion.fps, np.float32)}))

