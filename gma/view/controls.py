"""Body controls of the viewer (the paper's "SMPL transformation" module) and pose-sequence playback.

The pose of a frame is: the sequence's pose (or the canonical pose), with the hand curl applied to the
finger bones. Bone transforms for every frame of a sequence are computed in one batched forward-
kinematics call when the sequence, the shape or the hand curl changes, so playing a frame only uploads
[J, 4, 4] floats. Expressions (sliders + the sequence's own) change the rest vertices instead.
"""

from __future__ import annotations

import math
import re
import time
from pathlib import Path

import torch

from gma.body.motion_files import load_motion_file
from gma.body.motions import MOTIONS, axis_angle_to_matrix, motion
from gma.core.errors import MissingFileError
from gma.view.source import BodySource

__all__ = ["BodyControls", "load_motion"]

# Anny finger bones that bend when the hand closes (thumbs excluded: they fold across the palm).
_FINGER = re.compile(r"^finger[2-5]-[123]\.(L|R)$")
_THUMB = re.compile(r"^finger1-[23]\.(L|R)$")


def load_motion(spec: str, body, frames: int = 120):
    """A pose sequence: a built-in motion name (``walk``, ...), a motion file (``gma import motion``
    output, BVH, AMASS / SMPL-X npz) or a ``body.npz`` / sequence directory."""
    if spec in MOTIONS:
        return motion(spec, frames, body)
    path = Path(spec)
    if path.is_dir():
        path = path / "body.npz"
    if not path.is_file():
        raise MissingFileError(f"motion {spec!r}: neither a built-in motion ({', '.join(MOTIONS)}) nor a file")
    return load_motion_file(path, body)


class BodyControls:
    """Shape, expression, hand curl and playback state for a :class:`BodySource` (Anny rig)."""

    def __init__(self, source: BodySource):
        self.source = source
        body = source.body
        spaces = body.param_spaces
        self.shape_space, self.expression_space = spaces["shape"], spaces["expression"]
        # Start from the source's own identity (an avatar opens at its fitted shape and expression, not
        # at the body's default ones).
        self.shape = source.params["shape"].clone()
        self.expression = source.params["expression"].clone()
        self.hand_curl = [0.0, 0.0]  # left, right in [0, 1]
        self.motion = None
        self.frame = 0
        self.playing = False
        self._clock = 0.0
        self._cache_key = None
        self._transforms: torch.Tensor | None = None  # [T, J, 4, 4] of the current sequence
        self._fingers = [(i, m.group(1)) for i, n in enumerate(body.bone_names)
                         if (m := _FINGER.match(n) or _THUMB.match(n))]
        self.apply()

    # -- state changes (each re-poses the body) -------------------------------------------------------
    def set_motion(self, motion) -> None:
        """Play ``motion`` (a :class:`gma.body.Motion`) or return to the canonical pose (None)."""
        self.motion, self.frame, self._clock = motion, 0, 0.0
        self.playing = motion is not None
        self._cache_key = None
        self.apply()

    def reset_pose(self) -> None:
        """The canonical pose (A-pose for Anny), playback stopped, shape and expression kept."""
        self.set_motion(None)

    def shape_range(self, index: int) -> tuple[float, float]:
        """Slider range of shape entry ``index`` (SMPL-X betas have no declared range: ±3 std)."""
        sp = self.shape_space
        if sp.low is None or sp.high is None:
            return -3.0, 3.0
        return float(sp.low[index]), float(sp.high[index])

    def set_shape(self, index: int, value: float) -> None:
        lo, hi = self.shape_range(index)
        self.shape = self.shape.clone()
        self.shape[index] = min(max(float(value), lo), hi)
        self.apply()

    def set_expression(self, index: int, value: float) -> None:
        self.expression = self.expression.clone()
        self.expression[index] = min(max(float(value), 0.0), 1.0)
        self.apply()

    def set_hand_curl(self, side: int, amount: float) -> None:
        """``side`` 0 = left, 1 = right; ``amount`` 0 (open) .. 1 (fist)."""
        self.hand_curl[side] = min(max(float(amount), 0.0), 1.0)
        self.apply()

    def scrub(self, frame: int) -> None:
        if self.motion is not None:
            self.frame = int(frame) % len(self.motion)
            self._clock = self.frame / self.motion.fps
            self.apply()

    @property
    def num_frames(self) -> int:
        return len(self.motion) if self.motion is not None else 1

    def advance(self, dt: float) -> bool:
        """Advance playback by ``dt`` seconds; True when the frame changed."""
        if not self.playing or self.motion is None:
            return False
        self._clock += dt
        frame = int(self._clock * self.motion.fps) % len(self.motion)
        if frame == self.frame:
            return False
        self.frame = frame
        self.apply()
        return True

    # -- posing ---------------------------------------------------------------------------------------
    def _poses(self) -> torch.Tensor:
        """[T, J, 4, 4] local-ref pose deltas of the sequence (T = 1 for the canonical pose), hands applied."""
        body = self.source.body
        pose = self.motion.pose.clone() if self.motion is not None else body.canonical_pose()[None].clone()
        for bone, side in self._fingers:
            curl = self.hand_curl[0 if side == "L" else 1]
            if curl <= 0:
                continue
            # local-ref deltas rotate about world-aligned axes; in Anny's rest A-pose the fingers point
            # down and out, and closing the hand turns them about the world Y (front-back) axis.
            sign = -1.0 if side == "L" else 1.0
            rot = torch.eye(4)
            rot[:3, :3] = axis_angle_to_matrix(torch.tensor([0.0, sign * curl * math.radians(80), 0.0]))
            pose[:, bone] = rot @ pose[:, bone]
        return pose

    def apply(self) -> None:
        """Push the current state to the source (rest vertices when shape/expression changed, bones)."""
        src = self.source
        expr = self.expression
        if self.motion is not None and self.motion.expression.abs().sum() > 0:
            expr = (expr + self.motion.expression[self.frame % len(self.motion)]).clamp(0, 1)
        key = (self.shape.numpy().tobytes(), tuple(self.hand_curl), id(self.motion))
        if key != self._cache_key:
            t0 = time.perf_counter()
            with torch.no_grad():
                poses = self._poses()
                params = {"shape": self.shape, "expression": torch.zeros_like(expr)}
                self._transforms = src.body.bone_transforms({**params, "pose": poses})
                if self._transforms.dim() == 3:
                    self._transforms = self._transforms[None]
            src.set_params({"shape": self.shape, "expression": expr, "pose": poses[0]})
            self._cache_key = key
            self.last_pose_ms = (time.perf_counter() - t0) * 1e3
        else:
            src.set_expression(expr)
        src.set_bone_transforms(self._transforms[self.frame % len(self._transforms)])
