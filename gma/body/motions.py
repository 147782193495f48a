"""Built-in motions for the default (Anny) body, and Anny pose sequences from a sequence's ``body.npz``.

The built-ins are procedural joint rotations on Anny's 104-bone rig in its ``local-ref``
parameterisation (each delta a rotation about world-aligned axes at the bone, applied in the parent's
posed frame). Anny is Z-up, faces −Y and its left side is +X, so with rotations about:

- X: a leg or arm swings forward for a negative angle (the limb end moves towards −Y);
- Y: the left arm rises for a negative angle, the right arm for a positive one;
- Z: the root turns the whole body (positive = counter-clockwise seen from above).

``motion(name, frames)`` returns a :class:`Motion`; ``MOTIONS`` lists the names.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gma.body.params import load_body as load_sequence_body
from gma.body.registry import load_body

__all__ = ["MOTIONS", "Motion", "axis_angle_to_matrix", "load_anny_motion", "motion"]

MOTIONS = ("turn", "walk", "wave", "expressions")


@dataclass
class Motion:
    """A pose sequence for the Anny rig: ``pose`` [T, J, 4, 4] local-ref deltas, ``expression`` [T, 52]
    facial action weights (zeros when the motion has none), ``shape`` [6] phenotype, ``fps``."""

    name: str
    pose: torch.Tensor
    expression: torch.Tensor
    shape: torch.Tensor
    fps: float = 30.0

    def __len__(self) -> int:
        return int(self.pose.shape[0])

    def params(self, t: int) -> dict[str, torch.Tensor]:
        """Body parameters of frame ``t`` (wraps around, so the built-ins loop)."""
        t = t % len(self)
        return {"pose": self.pose[t], "expression": self.expression[t], "shape": self.shape}


def axis_angle_to_matrix(aa: torch.Tensor) -> torch.Tensor:
    """Rodrigues: axis-angle [..., 3] (radians) → rotation matrices [..., 3, 3]; exact at zero."""
    theta = aa.norm(dim=-1, keepdim=True)
    k = aa / theta.clamp_min(1e-12)
    kx, ky, kz = k.unbind(-1)
    zero = torch.zeros_like(kx)
    K = torch.stack([zero, -kz, ky, kz, zero, -kx, -ky, kx, zero], -1).reshape(*aa.shape[:-1], 3, 3)
    s, c = torch.sin(theta)[..., None], torch.cos(theta)[..., None]
    eye = torch.eye(3, dtype=aa.dtype).expand(*aa.shape[:-1], 3, 3)
    return eye + s * K + (1 - c) * (K @ K)


class _Rig:
    """Accumulates per-bone axis-angles [T, J, 3] by bone name, then builds the [T, J, 4, 4] deltas."""

    def __init__(self, bone_names: tuple[str, ...], frames: int):
        self.names = bone_names
        self.aa = torch.zeros(frames, len(bone_names), 3)
        self.root_translation = torch.zeros(frames, 3)

    def rotate(self, bone: str, axis: int, angle: torch.Tensor | float) -> None:
        if bone not in self.names:
            raise ValueError(f"built-in motions need bone {bone!r}, which this rig lacks")
        self.aa[:, self.names.index(bone), axis] += angle

    def deltas(self) -> torch.Tensor:
        # Composing per-axis angles as one axis-angle is exact for single-axis bones and a close
        # approximation for the small multi-axis ones used here.
        out = torch.eye(4).repeat(*self.aa.shape[:2], 1, 1)
        out[..., :3, :3] = axis_angle_to_matrix(self.aa)
        out[:, 0, :3, 3] = self.root_translation
        return out


X, Y, Z = 0, 1, 2


def _relaxed_arms(rig: _Rig, amount: float = 0.35) -> None:
    """Bring the A-pose arms closer to the body (left down = +Y, right down = −Y)."""
    rig.rotate("upperarm01.L", Y, amount)
    rig.rotate("upperarm01.R", Y, -amount)


def _turn(rig: _Rig, t: torch.Tensor) -> None:
    rig.rotate("root", Z, 2 * math.pi * t)  # one full turn over the clip, A-pose


def _walk(rig: _Rig, t: torch.Tensor, cycles: float = 2.0) -> None:
    phase = 2 * math.pi * cycles * t
    s = torch.sin(phase)
    _relaxed_arms(rig, 0.55)
    for side, sign in (("L", 1.0), ("R", -1.0)):
        swing = sign * s  # legs in anti-phase
        rig.rotate(f"upperleg01.{side}", X, -0.45 * swing)  # thigh forward on the negative side
        # The knee bends while the thigh moves forward (swing phase), most as it passes the vertical.
        knee = 0.55 * torch.clamp(sign * torch.cos(phase), min=0.0) + 0.08
        rig.rotate(f"lowerleg01.{side}", X, knee)
        rig.rotate(f"foot.{side}", X, -0.2 * swing)
        # Arms swing opposite to the leg of the same side; elbows slightly bent.
        rig.rotate(f"upperarm01.{side}", X, 0.35 * swing)
        rig.rotate(f"lowerarm01.{side}", X, -0.25 - 0.1 * swing)
    rig.rotate("spine02", Z, 0.08 * s)  # shoulders counter-rotate against the hips
    rig.rotate("root", Z, -0.05 * s)
    rig.root_translation[:, 2] = 0.015 * torch.cos(2 * phase)  # bob twice per cycle


def _wave(rig: _Rig, t: torch.Tensor, waves: float = 4.0) -> None:
    _relaxed_arms(rig, 0.0)
    rig.rotate("upperarm01.L", Y, 0.4)  # left arm relaxed
    # Raise the right arm smoothly during the first fifth, wave, lower during the last fifth.
    up = torch.clamp(torch.minimum(t / 0.2, (1 - t) / 0.2), 0.0, 1.0)
    up = up * up * (3 - 2 * up)  # smoothstep
    rig.rotate("upperarm01.R", Y, 1.55 * up)  # out and up to about shoulder height
    rig.rotate("upperarm01.R", X, -0.25 * up)  # slightly in front of the body
    rig.rotate("lowerarm01.R", Y, 1.3 * up + 0.35 * up * torch.sin(2 * math.pi * waves * t))  # forearm
    rig.rotate("wrist.R", Y, 0.25 * up * torch.sin(2 * math.pi * waves * t + 0.6))
    rig.rotate("neck01", Z, -0.15 * up)  # look towards the hand
    rig.rotate("spine02", Y, 0.05 * up)


# Expression keyframes: facial action weights, held and blended with smoothstep.
_EXPRESSIONS: tuple[dict[str, float], ...] = (
    {},
    {"mouthSmileLeft": 0.9, "mouthSmileRight": 0.9, "cheekSquintLeft": 0.4, "cheekSquintRight": 0.4},
    {"jawOpen": 0.6, "browInnerUp": 0.9, "browOuterUpLeft": 0.7, "browOuterUpRight": 0.7,
     "eyeWideLeft": 0.8, "eyeWideRight": 0.8},
    {"eyeBlinkLeft": 1.0, "mouthSmileLeft": 0.6},
    {"browDownLeft": 0.8, "browDownRight": 0.8, "mouthFrownLeft": 0.7, "mouthFrownRight": 0.7,
     "noseSneerLeft": 0.4, "noseSneerRight": 0.4},
    {"mouthPucker": 0.9, "mouthFunnel": 0.3},
    {},
)


def _expressions(rig: _Rig, t: torch.Tensor, labels: tuple[str, ...]) -> torch.Tensor:
    keys = torch.zeros(len(_EXPRESSIONS), len(labels))
    for i, frame in enumerate(_EXPRESSIONS):
        for name, w in frame.items():
            keys[i, labels.index(name)] = w
    pos = t * (len(_EXPRESSIONS) - 1)
    i0 = pos.floor().long().clamp(max=len(_EXPRESSIONS) - 2)
    a = (pos - i0).clamp(0, 1)
    a = a * a * (3 - 2 * a)
    weights = keys[i0] * (1 - a)[:, None] + keys[i0 + 1] * a[:, None]
    rig.rotate("neck01", X, 0.06 * torch.sin(2 * math.pi * 2 * t))  # a gentle nod keeps it alive
    rig.rotate("head", Z, 0.1 * torch.sin(2 * math.pi * t))
    _relaxed_arms(rig, 0.4)
    return weights


def motion(name: str, frames: int = 120, body=None, fps: float = 30.0,
           shape: torch.Tensor | None = None) -> Motion:
    """The built-in motion ``name`` (one of ``MOTIONS``) as ``frames`` frames looping seamlessly.

    ``body`` is the Anny body (its bone and facial action names); default: ``load_body("anny")``.
    """
    if name not in MOTIONS:
        raise ValueError(f"unknown motion {name!r}; built-in motions: {', '.join(MOTIONS)}")
    if frames < 1:
        raise ValueError(f"a motion needs at least one frame, got {frames}")
    if body is None:
        body = load_body("anny")
    if body.name != "anny":
        raise ValueError(f"built-in motions are for the Anny rig, not {body.name!r}")
    t = torch.arange(frames, dtype=torch.float32) / frames  # [0, 1): the last frame leads into the first
    rig = _Rig(body.bone_names, frames)
    labels = body.param_spaces["expression"].labels
    expression = torch.zeros(frames, len(labels))
    if name == "turn":
        _turn(rig, t)
    elif name == "walk":
        _walk(rig, t)
    elif name == "wave":
        _wave(rig, t)
    else:
        expression = _expressions(rig, t, labels)
    if shape is None:
        shape = body.param_spaces["shape"].default_tensor()
    return Motion(name, rig.deltas(), expression, shape, fps)


def load_anny_motion(path: str | Path, fps: float = 30.0) -> Motion:
    """An Anny pose sequence from a sequence's ``body.npz`` (``model`` = "anny": ``pose`` [T, 104, 4, 4],
    ``phenotype`` [6], optional ``facial_actions`` [T, 52]); read without pickle, validated by
    ``gma.body.params``."""
    seq = load_sequence_body(path)
    if seq.model != "anny":
        raise ValueError(f"{path}: holds {seq.model!r} body parameters, not an Anny pose sequence")
    a = seq.arrays
    pose = torch.as_tensor(np.asarray(a["pose"], np.float32))
    t = pose.shape[0]
    fa = a.get("facial_actions")
    expression = torch.zeros(t, 52) if fa is None else torch.as_tensor(np.asarray(fa, np.float32))
    shape = torch.as_tensor(np.asarray(a["phenotype"], np.float32))
    return Motion(Path(path).stem, pose, expression, shape, fps)
