"""Per-frame body pose corrections learnt while fitting (and, with the avatar frozen, at evaluation).

Poses estimated from a monocular video are off by a few degrees per bone and a few centimetres at the
root; fitted as they are, every error is baked into the avatar as blur. Like InstantAvatar, GART and
3DGS-Avatar, the fit therefore learns a small correction per frame:

- a rotation vector per refined bone (``BONE_SETS``: root, spine, neck, head, arms, legs, feet and their
  twist bones, shoulders, hips), applied
  on the left of the bone's Anny ``local-ref`` rotation, i.e. about world-aligned axes like the pose
  itself: ``R' = exp(δ) R``;
- a root translation ``Δt`` (metres), added to the root's translation.

Regularisers: a pull of the corrections to zero (toward the input poses) and a smoothness term between
frames adjacent in the sequence. Each frame's corrections are their own parameters, so Adam leaves a
frame untouched on steps that do not render it (one dense tensor would keep drifting on stale momentum).
Anny bodies only: SMPL-X pose corrections are not implemented.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import roma
import torch
from torch import nn
from tqdm import tqdm

from gma.body.params import save_body
from gma.core.errors import InputError
from gma.train.config import PoseRefineConfig
from gma.train.losses import picture_loss
from gma.train.metrics import separable_blur
from gma.train.render_step import render_frame

__all__ = ["BONE_SETS", "REFINE_BONES", "TEST_TIME_MSE", "PoseCorrections", "PoseRefineConfig", "apply_corrections",
           "fit_corrections", "refine_frozen", "refine_wanted", "save_refined_body"]

# The bones whose rotation is corrected (``--pose.bones``). "video": the ones the video fit estimates
# (gma.video.rig.FIT_BONES), without fingers: at fitting resolution a finger covers a pixel or two.
VIDEO_BONES = (
    "root", "spine05", "spine04", "spine03", "spine02", "spine01", "neck01", "neck02", "head",
    "clavicle.L", "upperarm01.L", "lowerarm01.L", "wrist.L",
    "clavicle.R", "upperarm01.R", "lowerarm01.R", "wrist.R",
    "upperleg01.L", "lowerleg01.L", "foot.L", "upperleg01.R", "lowerleg01.R", "foot.R",
)
# "body" (the default) adds the bones the video fit leaves at rest but that carry skin of the arms, legs,
# shoulders, hips and neck: the twist halves of the limbs (Anny splits each limb bone in two; a sleeve
# or trouser leg turns with the second), the shoulders, the hips and the upper neck. Each turns the skin
# it carries and the bones below it (a thigh's twist turns the knee and foot with it), under the same
# pull toward the input pose. iPER clip, last quarter, the same
# refined avatar, 300 test-time steps, bbox PSNR: 26.16 dB with the video's bones, 26.42 with these
# (every held-out frame up 0.13-0.61 dB).
BODY_EXTRA_BONES = (
    "shoulder01.L", "upperarm02.L", "lowerarm02.L", "shoulder01.R", "upperarm02.R", "lowerarm02.R",
    "pelvis.L", "upperleg02.L", "lowerleg02.L", "pelvis.R", "upperleg02.R", "lowerleg02.R", "neck03",
)
BONE_SETS = {"body": VIDEO_BONES + BODY_EXTRA_BONES, "video": VIDEO_BONES}
REFINE_BONES = BONE_SETS["body"]
# What ``gma import video`` writes into every sequence it estimates (gma.video.pipeline.REPORT_NAME):
# its presence marks poses that were estimated, not measured.
VIDEO_MARKER = "video_report.json"
# Translation corrections are regularised in units of this length (m): a root turn of 0.1 rad moves
# the torso's surface (~0.3 m from the axis) by about as much as a 3 cm shift.
TRANSL_UNIT = 0.3


def refine_wanted(cfg: PoseRefineConfig, seq) -> bool:
    """Whether sequence ``seq`` gets pose corrections under ``cfg.refine`` (auto: only estimated poses)."""
    if cfg.refine == "auto":
        return seq.body.model == "anny" and (Path(seq.root) / VIDEO_MARKER).is_file()
    if cfg.refine == "on" and seq.body.model != "anny":
        raise InputError(f"{seq.root}: pose refinement supports Anny sequences only, this one is "
                         f"{seq.body.model!r} (use --pose.refine off)")
    return cfg.refine == "on"


def apply_corrections(pose: torch.Tensor, bone_index: torch.Tensor, rotvec: torch.Tensor,
                      transl: torch.Tensor) -> torch.Tensor:
    """Corrected Anny local-ref pose [..., J, 4, 4]: bones ``bone_index`` [B] rotated by ``rotvec``
    [..., B, 3] about world-aligned axes (left-multiplied), root translation shifted by ``transl`` [..., 3].
    Out of place, differentiable in ``rotvec`` and ``transl``."""
    rot = roma.rotvec_to_rotmat(rotvec)                                     # [..., B, 3, 3]
    sel = pose[..., bone_index, :3, :3]
    full_rot = pose[..., :3, :3].index_copy(-3, bone_index, rot @ sel)
    t = pose[..., :3, 3:]
    root_t = t[..., :1, :, :] + transl[..., None, :, None]
    t = torch.cat([root_t, t[..., 1:, :, :]], -3)
    return torch.cat([torch.cat([full_rot, t], -1), pose[..., 3:, :]], -2)


class PoseCorrections(nn.Module):
    """Learnable corrections of T frames' poses. ``poses`` [T, J, 4, 4] are the input (local-ref) poses,
    ``order`` [T] each frame's position in the sequence (neighbours in it are smoothed together)."""

    def __init__(self, body, poses: torch.Tensor, order: list[int], bones=REFINE_BONES):
        super().__init__()
        self.register_buffer("poses", poses.detach().clone(), persistent=False)
        self.bone_index = torch.tensor([body.bone_index(b) for b in bones])
        t = poses.shape[0]
        self.rot = nn.ParameterList([nn.Parameter(torch.zeros(len(bones), 3)) for _ in range(t)])
        self.transl = nn.ParameterList([nn.Parameter(torch.zeros(3)) for _ in range(t)])
        # Neighbours in the sequence (by frame number): frame positions sorted, then adjacent pairs.
        rank = np.argsort(np.asarray(order), kind="stable")
        self.neighbours: list[list[int]] = [[] for _ in range(t)]
        for a, b in zip(rank[:-1], rank[1:], strict=True):
            self.neighbours[int(a)].append(int(b))
            self.neighbours[int(b)].append(int(a))

    def __len__(self) -> int:
        return len(self.rot)

    def rotation_params(self) -> list[nn.Parameter]:
        return list(self.rot)

    def translation_params(self) -> list[nn.Parameter]:
        return list(self.transl)

    def pose(self, t: int, detach: bool = False) -> torch.Tensor:
        """Corrected pose [J, 4, 4] of frame ``t`` (``detach``: without gradients to the corrections)."""
        r, d = self.rot[t], self.transl[t]
        if detach:
            r, d = r.detach(), d.detach()
        return apply_corrections(self.poses[t], self.bone_index, r, d)

    def all_poses(self) -> torch.Tensor:
        """[T, J, 4, 4] corrected poses (no gradients)."""
        with torch.no_grad():
            return torch.stack([self.pose(t) for t in range(len(self))])

    def regulariser(self, t: int, cfg: PoseRefineConfig) -> torch.Tensor:
        """Prior toward the input pose plus smoothness against the (fixed) neighbours of frame ``t``:
        only frame ``t`` gets gradients, so a step changes only the frame it rendered."""
        r, d = self.rot[t], self.transl[t] / TRANSL_UNIT
        reg = cfg.prior * (r.pow(2).sum(-1).mean() + d.pow(2).sum())
        for n in self.neighbours[t]:
            rn, dn = self.rot[n].detach(), self.transl[n].detach() / TRANSL_UNIT
            reg = reg + cfg.smooth * ((r - rn).pow(2).sum(-1).mean() + (d - dn).pow(2).sum())
        return reg

    def summary(self) -> dict:
        """Mean rotation correction (degrees, over frames and bones; the root's separately) and mean root
        shift (cm)."""
        with torch.no_grad():
            ang = torch.stack(list(self.rot)).norm(dim=-1).rad2deg()      # [T, B]
            shift = torch.stack(list(self.transl)).norm(dim=-1) * 100     # [T]
        return {"mean_bone_deg": float(ang[:, 1:].mean()), "mean_root_deg": float(ang[:, 0].mean()),
                "max_bone_deg": float(ang.max()), "mean_root_shift_cm": float(shift.mean())}


def save_refined_body(path: Path, seq, indices: list[int], poses: torch.Tensor) -> None:
    """Write ``seq``'s ``body.npz`` with frames ``indices`` given the refined ``poses`` [T, J, 4, 4]
    (the other frames keep their input poses): a valid body.npz for the same sequence (atomic)."""
    arrays = {k: np.array(v, copy=True) for k, v in seq.body.arrays.items()}
    pose = arrays["pose"].astype(np.float32)
    p = poses.detach().numpy().astype(np.float64)
    # Re-orthonormalise: float32 products of rotations drift by ~1e-7, well inside the validator's 1e-3,
    # but a body.npz refined again and again should not accumulate it.
    u, _, vt = np.linalg.svd(p[..., :3, :3])
    p[..., :3, :3] = u @ vt
    pose[np.asarray(indices)] = p.astype(np.float32)
    arrays["pose"] = pose
    save_body(path, type(seq.body)(seq.body.model, arrays))



# Test-time fitting compares blurred pictures first: a Gaussian of COARSE_BLUR × the image's longer side
# (4 px at 192 px) that shrinks linearly to nothing by COARSE_UNTIL of the steps. A limb a few pixels off
# its place in the image gets no pull from a sharp loss once its edges no longer overlap; blurred, the
# loss slopes toward it. iPER clip, last quarter, 60 steps, bbox PSNR: 25.29 -> 25.47 dB (100 steps:
# 25.41 -> 25.62); sigma 2 or 3 px for the first half: 25.41, 5 px: 25.36, 6 px shrinking: 25.48.
# Synthetic video benchmark, held-out poses: 25.76 -> 25.80.
COARSE_BLUR = 4.0 / 192
COARSE_UNTIL = 0.7

# Test-time fitting weighs the mean squared colour error too (beside 0.8 L1 + 0.2 SSIM): PSNR is what
# refined poses are scored on, and L1 alone lets a few badly matched pixels (a loose sleeve's edge) stay
# badly matched. iPER clip, last quarter, 300 steps, bbox PSNR: 26.01 -> 26.17 dB (every held-out frame up
# 0.1-0.7 dB; the squared error alone 26.14). The fit's alignment pass does not use it (with it there too:
# 26.13 against 26.17).
TEST_TIME_MSE = 10.0


def blurred(image: torch.Tensor, sigma: float) -> torch.Tensor:
    """``image`` [H, W, C] through a separable Gaussian of ``sigma`` pixels, edges repeated (so a border
    does not darken); differentiable."""
    radius = max(1, int(3 * sigma))
    x = torch.arange(-radius, radius + 1, dtype=image.dtype, device=image.device)
    k = torch.exp(-0.5 * (x / sigma) ** 2)
    k = k / k.sum()
    return separable_blur(image.permute(2, 0, 1)[None], k, mode="replicate")[0].permute(1, 2, 0)


def coarse_sigma(step: int, steps: int, size: int) -> float:
    """Blur (pixels) of test-time step ``step`` of ``steps`` at images of longer side ``size``; 0: sharp."""
    sigma = COARSE_BLUR * size * (1 - step / (COARSE_UNTIL * steps))
    return sigma if sigma > 0.3 else 0.0   # below a third of a pixel the kernel is a single tap


def refine_frozen(decoded, body, frames, steps: int, cfg: PoseRefineConfig, background: float = 0.5,
                  ctx=None, progress: bool = False, colour=None, colour_cfg=None, cull: bool = False
                  ) -> PoseCorrections:
    """Test-time pose fitting (the PeopleSnapshot protocol of Anim-NeRF / InstantAvatar): each frame's
    corrections optimised for ``steps`` Adam steps against its image and mask, with the avatar frozen
    (``decoded`` is used as it is; decode it under ``torch.no_grad``). Frames are independent (no
    smoothness); the prior still pulls toward the input pose. The first steps compare blurred pictures
    (see ``COARSE_BLUR``). ``colour`` (optional, a ``gma.train.appearance.FrameColour`` of the frames, with
    ``colour_cfg`` its learning rate and prior) is fitted with the poses. ``cull``: draw only the surfels of
    faces not turned away from the camera, as :func:`fit_corrections` explains; off by default, as frames
    are scored and shown with every surfel. Returns the corrections of ``frames``."""
    corr = PoseCorrections(body, frames.poses, frames.indices, BONE_SETS[cfg.bones])
    fit_corrections(corr, decoded, body, frames, steps, cfg, background, ctx, progress, mse=TEST_TIME_MSE,
                    colour=colour, colour_cfg=colour_cfg, cull=cull)
    return corr


def fit_corrections(corr: PoseCorrections, decoded, body, frames, steps: int, cfg: PoseRefineConfig,
                    background: float = 0.5, ctx=None, progress: bool = False, desc: str = "refine poses",
                    mse: float = 0.0, colour=None, colour_cfg=None, cull: bool = False) -> None:
    """Each frame's corrections in ``corr`` (from where they are) fitted to its image for ``steps`` steps
    with the avatar ``decoded`` frozen: what :func:`refine_frozen` does, in place. ``mse``: weight of the
    mean squared colour error beside L1 and SSIM (test-time fitting: ``TEST_TIME_MSE``; the fit's alignment
    pass leaves it at 0). ``colour`` (optional): the frames' colour transforms
    (``gma.train.appearance.FrameColour``), fitted beside the poses under ``colour_cfg``'s rate and prior.
    ``cull``: draw only the surfels on faces not turned away from the camera (half the work). The poses
    are fitted to the picture drawn, so draw it as the result will be drawn: the surfels of faces turned
    away still show past the silhouette, and poses fitted without them misplace the outline."""
    size = max(frames.images.shape[1:3])
    bar = tqdm(total=len(frames) * steps, desc=desc, unit="step", disable=not progress, leave=False)
    for t in range(len(frames)):
        groups = [{"params": [corr.rot[t]], "lr": cfg.lr_rotation},
                  {"params": [corr.transl[t]], "lr": cfg.lr_translation}]
        if colour is not None:
            groups.append({"params": colour.params(t), "lr": colour_cfg.lr})
        opt = torch.optim.Adam(groups, eps=1e-15)
        base = [g["lr"] for g in opt.param_groups]
        target = frames.target(t, background)
        for i in range(steps):
            for g, lr in zip(opt.param_groups, base, strict=True):  # settle: 10x smaller steps by the end
                g["lr"] = lr * 0.1 ** (i / max(1, steps))
            bones = body.bone_transforms({"pose": corr.pose(t), "shape": frames.shape})
            out, _ = render_frame(decoded, body, frames, t, background, ctx, cull=cull, bones=bones)
            color = out.color if colour is None else colour.apply(t, out.color, out.alpha, background)
            want, alpha, mask = target, out.alpha, frames.masks[t]
            sigma = coarse_sigma(i, steps, size)
            if sigma:  # the four pictures through one blur: one pair of convolutions, not four
                parts = (color, want, alpha, mask)
                color, want, alpha, mask = blurred(torch.cat(parts, -1), sigma).split([x.shape[-1] for x in parts], -1)
            l1, dssim = picture_loss(color, want)
            r, d = corr.rot[t], corr.transl[t] / TRANSL_UNIT
            loss = (0.8 * l1 + 0.2 * dssim + mse * (color - want).pow(2).mean() + 0.1 * (alpha - mask).abs().mean()
                    + cfg.prior * (r.pow(2).sum(-1).mean() + d.pow(2).sum()))
            if colour is not None:
                loss = loss + colour_cfg.prior * colour.regulariser(t)
            loss.backward()
            opt.step()
            opt.zero_grad(set_to_none=True)
            bar.update(1)
    bar.close()
