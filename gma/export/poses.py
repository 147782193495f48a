"""Which poses an export writes: a named pose, a frame of the avatar's fitted sequence, or frames of a
motion file (every K-th frame as a numbered series)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import torch

from gma.avatar.avatar import Avatar
from gma.body.motion_files import load_motion_file
from gma.body.retarget import reference_pose
from gma.core.errors import InputError, MissingFileError

__all__ = ["NAMED_POSES", "ExportPose", "export_poses"]

NAMED_POSES = ("canonical", "tpose", "apose")


@dataclass
class ExportPose:
    """One pose to export: ``label`` (None for a single export, else the frame number used in the file
    name) and the body ``params`` (pose, expression; the avatar's shape is added by the exporters)."""

    label: str | None
    params: dict[str, torch.Tensor]


def _fitted_motion(avatar: Avatar, path: str | None):
    seq = avatar.info.get("sequence")
    if not seq:
        raise InputError(f"{path}: the avatar does not name the sequence it was fitted to; give --motion FILE "
                         "with --frame")
    body_npz = Path(seq) / "body.npz"
    if not body_npz.is_file():
        raise MissingFileError(f"{body_npz}: the avatar's fitted sequence is not there any more; give --motion FILE")
    return load_motion_file(body_npz)


def export_poses(avatar: Avatar, body, pose: str = "canonical", motion: str | None = None,
                 frame: int | None = None, every: int | None = None,
                 avatar_path: str | None = None) -> list[ExportPose]:
    """The poses to export. ``motion``: a motion file (``gma import motion`` output, a sequence's body.npz,
    BVH, AMASS npz); ``frame``: one frame of it (or of the fitted sequence when ``motion`` is None);
    ``every``: every K-th frame of the motion. With neither, the named ``pose``."""
    if motion is None and frame is None:
        if every is not None:
            raise InputError("--every needs --motion FILE")
        if pose not in NAMED_POSES:
            raise InputError(f"--pose must be one of {', '.join(NAMED_POSES)}, got {pose!r}")
        return [ExportPose(None, reference_pose(body, pose))]
    if body.name != "anny":
        raise InputError(f"{avatar_path}: motions drive Anny avatars; this one is bound to {body.name!r}")
    mot = load_motion_file(motion, body=body) if motion is not None else _fitted_motion(avatar, avatar_path)
    n = len(mot)

    def params(i: int) -> dict[str, torch.Tensor]:
        p = mot.params(i)
        return {"pose": p["pose"], "expression": p["expression"]}

    if frame is not None:
        if every is not None:
            raise InputError("give --frame N or --every K, not both")
        if frame >= n:
            raise InputError(f"--frame {frame}: the motion has {n} frames (0..{n - 1})")
        return [ExportPose(None, params(frame))]
    step = every or 1
    return [ExportPose(f"{i:05d}", params(i)) for i in range(0, n, step)]
