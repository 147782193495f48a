"""Fitting Anny to a clip's detections: per-frame pose (root rotation and translation, spine, neck,
head, arms, legs, feet, and fingers where hand landmarks exist) and one phenotype for the clip.

Energy (summed over frames; each term normalised so the weights are comparable):

- 2D reprojection of the model points (``gma.video.landmarks``) against the landmarks, in units of
  the person's size in pixels, with a Charbonnier (smooth L1) penalty so a few wrong landmarks do not
  dominate;
- 3D bone directions against MediaPipe's world landmarks (1 − cos), which fixes what one view cannot:
  whether a forearm points towards or away from the camera; and the same for the line between the
  eyes against the face mesh's where a face was found (the head's turn and roll);
- mask silhouette (``gma.video.silhouette``) on a few random frames per step, in the last stage;
- temporal smoothness of the model points (metres²) and root translation;
- soft joint limits (per-bone rotation angle beyond ``gma.video.rig.ANGLE_LIMITS``), a weak pull to
  the rest pose, and a weak pull of the phenotype to the average person (weak enough that a whole
  clip's silhouettes and landmarks decide the body shape: a turning person shows every side).

Frames without a detection have no data terms: smoothness interpolates them, and they start from the
interpolation of their neighbours' initial poses. Stages: (1) root only, on the torso; (2) all bones;
(3) all bones plus phenotype and silhouette.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import roma
import torch
from tqdm import tqdm

from gma.video.camera import CAMERA_FROM_WORLD
from gma.video.landmarks import POSE_POINTS
from gma.video.rig import AnnyRig
from gma.video.silhouette import SilhouetteRenderer, crop_box
from gma.video.targets import FitTargets

__all__ = ["FitConfig", "FitResult", "fit_body", "project"]

_TORSO = ("coco:left_shoulder", "coco:right_shoulder", "coco:left_hip", "coco:right_hip")


@dataclass
class FitConfig:
    """Body fit settings (iterations are Adam steps over all frames at once)."""

    iters_root: int = 60  # stage 1: root rotation and translation on the torso
    iters_pose: int = 200  # stage 2: all bones
    iters_shape: int = 150  # stage 3: all bones, phenotype, silhouette
    lr: float = 0.03  # Adam step size (radians / metres)
    w_2d: float = 1.0  # 2D reprojection
    w_3d: float = 0.3  # 3D directions (per pair × gma.video.landmarks.BONE_PAIR_WEIGHTS, FACE_PAIR_WEIGHTS)
    w_sil: float = 1.0  # mask silhouette (stage 3)
    w_smooth: float = 1.0  # temporal smoothness of model points (per m²)
    w_limit: float = 1.0  # joint limits (per rad²)
    w_prior: float = 0.002  # pull of bone rotations to the rest pose (per rad²)
    # Pull of the phenotype to 0.5. At 0.01 (with 60 stage-3 steps on 2 silhouettes each) the phenotype
    # stayed within 0.05 of average on the iPER clip; at 0.001 with 150 steps on 4 silhouettes it moved
    # (weight 0.71, muscle 0.28) and the fit got closer on both independent checks: mask IoU 0.738 ->
    # 0.768, landmark reprojection 6.0 -> 5.7 px; on a synthetic turn 0.769 -> 0.786 and 2.62 -> 2.39 px,
    # though the phenotype did not come closer to the true one there (gender 0.58 for 0.89): silhouettes
    # and landmarks do not pin the six phenotype values down one by one.
    w_shape: float = 0.001
    fit_shape: bool = True  # estimate the phenotype (else the average person)
    fit_hands: bool = True  # estimate finger bones where hand landmarks exist
    sil_frames: int = 4  # frames rendered per stage-3 step (the shape sees every side of a turning person)
    sil_size: int = 96  # silhouette crop size in pixels
    # Landmark tracks smoothed over this many frames either side (gma.video.smooth); 0: off. Off by default:
    # on the iPER turn the one-sided windows at the clip's end drew its last held-out frames 2-3 dB worse.
    smooth_frames: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        if not isinstance(self.smooth_frames, int) or self.smooth_frames < 0:
            raise ValueError(f"--smooth-frames: expected a whole number of frames >= 0, got {self.smooth_frames!r}")


@dataclass
class FitResult:
    """pose [T, J, 4, 4] Anny local-ref; phenotype [6]; points [T, P, 3] world model points;
    uv [T, P, 2] their projections; root_center [3] median root position before re-centring."""

    pose: np.ndarray
    phenotype: np.ndarray
    points: np.ndarray
    uv: np.ndarray
    losses: dict[str, float]


def project(points: torch.Tensor, K: torch.Tensor, R: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """Pixels [..., 2] of world points [..., 3] through x = K (R p + t)."""
    cam = points @ R.T + t
    z = cam[..., 2:].clamp_min(1e-3)
    return (cam[..., :2] / z) * torch.stack([K[0, 0], K[1, 1]]) + torch.stack([K[0, 2], K[1, 2]])


def _kabsch(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Rotation R [3, 3] minimising Σ‖R a_i − b_i‖² for centred point sets a, b [N, 3]."""
    u, _, vt = np.linalg.svd(b.T @ a)
    d = np.sign(np.linalg.det(u @ vt))
    return u @ np.diag([1, 1, d]) @ vt


def _initial_root(rig: AnnyRig, rest, tg: FitTargets, pose3d: np.ndarray, K: np.ndarray):
    """Per-frame root rotation vectors [T, 3] and translations [T, 3] (world): orientation from the 3D
    torso landmarks, position by linear least squares on the 2D landmarks."""
    zero = torch.zeros(1, len(rig.fit_bones), 3)
    base = rig.points(rig.transforms(rig.pose_matrices(zero, torch.zeros(1, 3)), rest), rest)[0].numpy()
    h0 = rest.rest_heads[0].numpy()
    mp_idx = [POSE_POINTS.index(n) for n in _TORSO]
    torso = [rig.index(n) for n in _TORSO]
    C = CAMERA_FROM_WORLD
    found = tg.found.numpy()
    T = len(found)
    rotvec, transl = np.zeros((T, 3)), np.zeros((T, 3))
    f, cx, cy = K[0, 0], K[0, 2], K[1, 2]
    for t in np.nonzero(found)[0]:
        a = (base[torso] - h0) @ C.T
        b = pose3d[t, mp_idx]
        if not np.isfinite(b).all():
            continue
        R_cam = _kabsch(a - a.mean(0), b - b.mean(0))
        R_root = C.T @ R_cam @ C
        X = (base - h0) @ C.T @ R_cam.T                                   # camera-frame offsets [P, 3]
        w = tg.conf[t].numpy()
        uv = tg.uv[t].numpy()
        rows, rhs = [], []
        for i in np.nonzero(w > 0.2)[0]:
            rows.append([f, 0, cx - uv[i, 0]])
            rhs.append(uv[i, 0] * X[i, 2] - f * X[i, 0] - cx * X[i, 2])
            rows.append([0, f, cy - uv[i, 1]])
            rhs.append(uv[i, 1] * X[i, 2] - f * X[i, 1] - cy * X[i, 2])
        if len(rows) < 6:
            continue
        c, *_ = np.linalg.lstsq(np.array(rows), np.array(rhs), rcond=None)
        if c[2] <= 0.1:  # behind or at the camera: the landmarks are inconsistent, leave it to neighbours
            continue
        rotvec[t] = roma.rotmat_to_rotvec(torch.from_numpy(R_root)).numpy()
        transl[t] = C.T @ c
    return _interpolate_missing(rotvec, transl, found & (np.abs(transl).sum(1) > 0))


def _interpolate_missing(rotvec: np.ndarray, transl: np.ndarray, ok: np.ndarray):
    """Fill frames where ``ok`` is False: translation linearly, rotation by slerp between the nearest
    good frames (constant beyond the ends)."""
    good = np.nonzero(ok)[0]
    if len(good) == 0:
        raise ValueError("no frame has a usable person detection")
    T = len(ok)
    for d in range(3):
        transl[:, d] = np.interp(np.arange(T), good, transl[good, d])
    q = roma.rotvec_to_unitquat(torch.from_numpy(rotvec))
    for t in np.nonzero(~ok)[0]:
        prev, nxt = good[good < t], good[good > t]
        if len(prev) == 0 or len(nxt) == 0:
            q[t] = q[(nxt if len(prev) == 0 else prev)[0 if len(prev) == 0 else -1]]
            continue
        a, b = prev[-1], nxt[0]
        s = torch.tensor([(t - a) / (b - a)], dtype=q.dtype)
        q[t] = roma.utils.unitquat_slerp(q[a], q[b], s)[0]
    return roma.unitquat_to_rotvec(q).numpy(), transl


def fit_body(rig: AnnyRig, tg: FitTargets, pose3d: np.ndarray, K: np.ndarray, masks: np.ndarray | None,
             cfg: FitConfig | None = None, progress: bool = True) -> FitResult:
    """Fit the body to targets ``tg`` seen by camera ``K`` [3, 3] (world→camera rotation
    ``CAMERA_FROM_WORLD``, camera at the origin). ``masks`` [T, H, W] enable the silhouette term."""
    cfg = cfg or FitConfig()
    torch.manual_seed(cfg.seed)
    fit = _BodyFit(rig, tg, pose3d, K, masks, cfg)
    stages = fit.stages()
    bar = tqdm(total=sum(s[1] for s in stages), desc="fit", unit="step", leave=False, disable=not progress)
    losses: dict[str, float] = {}
    for stage, iters, params in stages:
        if iters <= 0:
            continue
        opt = torch.optim.Adam(params, lr=cfg.lr)
        for _ in range(iters):
            opt.zero_grad()
            loss, losses = fit.energy(stage)
            loss.backward()
            if stage == 1:  # only the root moves in stage 1
                fit.rotvecs.grad[:, 1:] = 0
            opt.step()
            bar.update(1)
            bar.set_postfix(stage=stage, loss=f"{float(loss.detach()):.4f}")
    bar.close()
    return fit.result(losses)


class _BodyFit:
    """The variables of one body fit (root and bone rotations, translations, phenotype logits) and its
    energy: 2D landmarks from stage 1 (torso only there), 3D directions, joint limits and a pose prior
    from stage 2, phenotype and silhouette in stage 3; smoothness over time throughout."""

    def __init__(self, rig: AnnyRig, tg: FitTargets, pose3d: np.ndarray, K: np.ndarray,
                 masks: np.ndarray | None, cfg: FitConfig):
        self.rig, self.tg, self.cfg = rig, tg, cfg
        self.T = len(tg.found)
        self.Kt = torch.as_tensor(K, dtype=torch.float32)
        self.R = torch.as_tensor(CAMERA_FROM_WORLD, dtype=torch.float32)
        self.tcam = torch.zeros(3)
        self.pheno_logit = torch.zeros(6, requires_grad=True)
        self.rest = rig.rest(torch.full((6,), 0.5))
        with torch.no_grad():
            rv0, tr0 = _initial_root(rig, self.rest, tg, pose3d, K)
        n_bones = len(rig.fit_bones) if (cfg.fit_hands and len(rig.fit_bones) > 23) else 23
        self.rotvecs = torch.zeros(self.T, n_bones, 3)
        self.rotvecs[:, 0] = torch.as_tensor(rv0, dtype=torch.float32)
        self.rotvecs.requires_grad_(True)
        self.transl = torch.as_tensor(tr0, dtype=torch.float32).clone().requires_grad_(True)
        self.limits = rig.limits[: n_bones - 1]
        self.torso = torch.tensor([rig.index(n) for n in _TORSO])
        self.sil = None
        if masks is not None and cfg.iters_shape > 0 and cfg.w_sil > 0:
            self.sil = SilhouetteRenderer(rig.body.faces, size=cfg.sil_size, seed=cfg.seed)
            self.boxes = [crop_box(m) if tg.found[t] else None for t, m in enumerate(masks)]
            self.sil_frames = [t for t, b in enumerate(self.boxes) if b is not None]
            self.targets = {t: self.sil.target(masks[t], self.boxes[t]) for t in self.sil_frames}
        self.w2c = torch.eye(4)
        self.w2c[:3, :3] = self.R
        self.g = torch.Generator().manual_seed(cfg.seed)

    def stages(self) -> list[tuple[int, int, list[dict]]]:
        """(stage, steps, Adam parameter groups) of the three stages."""
        cfg = self.cfg
        # Stage 3 sees the silhouette of only a few frames per step; at the full step size Adam would
        # jolt exactly those frames' poses each time, so poses move 5× slower there than the phenotype.
        poses = [{"params": [self.rotvecs, self.transl]}]
        return [(1, cfg.iters_root, poses), (2, cfg.iters_pose, poses),
                (3, cfg.iters_shape, [{"params": [self.rotvecs, self.transl], "lr": cfg.lr * 0.2}]
                 + ([{"params": [self.pheno_logit]}] if cfg.fit_shape else []))]

    def energy(self, stage: int) -> tuple[torch.Tensor, dict[str, float]]:
        cfg, tg = self.cfg, self.tg
        if stage == 3 and cfg.fit_shape:
            self.rest = self.rig.rest(torch.sigmoid(self.pheno_logit))
        pose = self.rig.pose_matrices(self.rotvecs, self.transl)
        tr = self.rig.transforms(pose, self.rest)
        pts = self.rig.points(tr, self.rest)                              # [T, P, 3]
        uv = project(pts, self.Kt, self.R, self.tcam)
        conf = tg.conf if stage > 1 else tg.conf * torch.isin(torch.arange(pts.shape[1]), self.torso)
        err = (uv - tg.uv).norm(dim=-1) / tg.scale[:, None]
        e2d = (conf * (torch.sqrt(err**2 + 1e-4) - 1e-2)).sum() / conf.sum().clamp_min(1e-6)
        terms = {"2d": cfg.w_2d * e2d}
        if stage > 1:
            terms.update(self._pose_terms(pts))
        if self.T > 1:
            terms["smooth"] = cfg.w_smooth * ((pts[1:] - pts[:-1]).pow(2).sum(-1).mean()
                                              + (self.transl[1:] - self.transl[:-1]).pow(2).sum(-1).mean())
        if stage == 3:
            terms["shape"] = cfg.w_shape * (torch.sigmoid(self.pheno_logit) - 0.5).pow(2).sum()
            if self.sil is not None and self.sil_frames:
                terms["sil"] = cfg.w_sil * self._silhouette(tr)
        total = sum(terms.values())
        return total, {k: float(v.detach()) for k, v in terms.items()}

    def _pose_terms(self, pts: torch.Tensor) -> dict[str, torch.Tensor]:
        """3D bone directions against the landmarks', joint limits and the pose prior."""
        cfg, tg = self.cfg, self.tg
        cam = pts @ self.R.T
        d = cam[:, tg.pair_idx[:, 1]] - cam[:, tg.pair_idx[:, 0]]
        cos = (d / d.norm(dim=-1, keepdim=True).clamp_min(1e-6) * tg.dirs3d).sum(-1)
        ang = self.rotvecs[:, 1:].norm(dim=-1)
        return {"3d": cfg.w_3d * (tg.conf3d * tg.pair_w * (1 - cos)).sum() / tg.conf3d.sum().clamp_min(1e-6),
                "limit": cfg.w_limit * torch.relu(ang - self.limits).pow(2).sum(-1).mean(),
                "prior": cfg.w_prior * ang.pow(2).sum(-1).mean()}

    def _silhouette(self, tr: torch.Tensor) -> torch.Tensor:
        """Mean squared silhouette error over a few random frames (``cfg.sil_frames``)."""
        pick = torch.randperm(len(self.sil_frames), generator=self.g)[: self.cfg.sil_frames]
        verts = self.rig.vertices(tr[[self.sil_frames[i] for i in pick]], self.rest)
        e = 0
        for k, i in enumerate(pick):
            t = self.sil_frames[i]
            a = self.sil.render(verts[k], self.Kt, self.w2c, self.boxes[t])
            e = e + (a - self.targets[t]).pow(2).mean()
        return e / len(pick)

    def result(self, losses: dict[str, float]) -> FitResult:
        with torch.no_grad():
            pheno = torch.sigmoid(self.pheno_logit) if self.cfg.fit_shape else torch.full((6,), 0.5)
            rest = self.rig.rest(pheno)
            pose = self.rig.pose_matrices(self.rotvecs, self.transl)
            pts = self.rig.points(self.rig.transforms(pose, rest), rest)
            uv = project(pts, self.Kt, self.R, self.tcam)
        return FitResult(pose.numpy(), pheno.numpy(), pts.numpy(), uv.numpy(), losses)
