"""The two-stage fit (``gma fit``): stage 1 fits geometry through one coarse surfel per face (the mesh
layer), stage 2 the fine surfels with F_coarse and f_geo frozen. Ablations switch to one stage, to the
mesh layer only, or to direct per-surfel parameters. Several sequences fit one avatar each around one
set of shared decoders (written to ``decoders.gma`` for ``--decoders``).

Everything a run produces lands in a work folder beside the output (``avatar.gma`` -> ``avatar.fit/``):
``config.json`` (resolved), ``checkpoint.safetensors`` (atomic, every ``checkpoint_every`` steps),
``metrics.json`` (loss history, timing split), ``previews/`` (render | target images).

Sequences with estimated poses (from ``gma import video``) also learn per-frame pose corrections
(``gma.train.pose_refine``); the refined poses are written beside the avatar as ``<avatar>.body.npz``, a
``body.npz`` for the same sequence.
"""

from __future__ import annotations

import dataclasses
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path

import torch
from tqdm import tqdm

from gma.avatar.avatar import Avatar
from gma.avatar.decoders import load_decoders, save_decoders
from gma.body import load_body
from gma.core.atomic import atomic_write_json
from gma.core.errors import NonFiniteError
from gma.render.image_io import save_png
from gma.train.appearance import FrameColour, colour_wanted, colour_weights, unmix_background, weighted_picture_loss
from gma.train.checkpoint import load_checkpoint, save_checkpoint
from gma.train.config import FitConfig, LossWeights
from gma.train.data import FrameSet, load_frames
from gma.train.losses import GeometryTerms, load_lpips, normal_consistency
from gma.train.metrics import psnr
from gma.train.pose_refine import BONE_SETS, PoseCorrections, fit_corrections, refine_wanted, save_refined_body
from gma.train.render_step import render_frame
from gma.train.symmetry import DEAD_ZONE, SymmetryPrior

__all__ = ["CHECKPOINT_NAME", "Stage", "Trainer", "refined_body_path", "work_dir"]

# The checkpoint inside a fit's work folder (gma.train.outputs and gma batch look for it there too).
CHECKPOINT_NAME = "checkpoint.safetensors"


def work_dir(out: Path) -> Path:
    """The folder holding a fit's config, checkpoint, metrics and previews: ``<out>.fit`` beside it."""
    return out.with_name(out.stem + ".fit")


def refined_body_path(out: Path) -> Path:
    """Where a fit with pose refinement writes the refined poses: ``<out>.body.npz`` beside the avatar."""
    return out.with_name(out.stem + ".body.npz")


@dataclass
class Stage:
    """One training stage: which layer renders, how long, with which weights, and which groups learn."""

    name: str
    layer: str  # "coarse" or "fine"
    steps: int
    weights: LossWeights
    groups: tuple[str, ...]  # AvatarModel.param_groups names that learn
    resolution: int  # longest image side the stage renders at


def plan_stages(cfg: FitConfig) -> list[Stage]:
    """The stages of a fit. ``direct`` binding has no mesh layer for a geometry stage to fit, so it trains
    its surfels in one stage of all the steps, like one-stage training."""
    rep = cfg.avatar.representation
    fine = "coarse" if rep == "mesh_only" else "fine"
    if cfg.training == "one_stage" or rep == "direct":
        w = LossWeights(**{**cfg.weights1.__dict__, "lpips": cfg.weights2.lpips})
        return [Stage("one_stage", fine, cfg.total_steps, w, ("geo_coarse", "geo_fine", "tex"), cfg.resolution)]
    return [Stage("stage1", "coarse", cfg.stage1_steps, cfg.weights1, ("geo_coarse", "tex"),
                  min(cfg.stage1_resolution or cfg.resolution, cfg.resolution)),
            Stage("stage2", fine, cfg.stage2_steps, cfg.weights2, ("geo_fine", "tex"), cfg.resolution)]


@dataclass
class Subject:
    """One sequence being fitted: its training frames, its avatar, and the file the avatar goes to."""

    name: str
    seq: object
    frames: FrameSet
    avatar: Avatar
    out: Path
    poses: PoseCorrections | None = None  # learnt pose corrections (sequences with estimated poses)
    colours: FrameColour | None = None  # learnt per-frame colour transforms (sequences from a video)
    # The frames at each stage's resolution, with each pixel's colour-loss weight [T, H, W, 1] (None: 1).
    views: dict[int, tuple[FrameSet, torch.Tensor | None]] = dataclasses.field(default_factory=dict)

    def view(self, resolution: int) -> tuple[FrameSet, torch.Tensor | None]:
        return self.views[resolution]


def subject_outputs(out: Path, roots: list) -> list[Path]:
    """Avatar files of a fit of the sequences in folders ``roots``: ``out`` itself for one sequence;
    ``out/<sequence folder name>.gma`` for several (then ``out`` is a folder, which also receives
    ``decoders.gma``). Only the folder names count, so outputs are known before any sequence is read."""
    if len(roots) == 1:
        return [out]
    if out.suffix == ".gma":
        raise ValueError(f"{out}: with several sequences, -o names a folder (one avatar per sequence and the "
                         "shared decoders.gma go there)")
    names = [Path(r).name or f"seq{i}" for i, r in enumerate(roots)]
    seen: dict[str, int] = {}
    outs = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        outs.append(out / (f"{name}.gma" if names.count(name) == 1 else f"{name}_{seen[name]}.gma"))
    return outs


# Fit options added after fits were already being made, with the value that reproduces what a fit did
# before (a checkpoint from then resumes with it rather than failing the same-config check). A dotted
# name is a field of a nested section (``pose.align``: ``FitConfig.pose.align``).
OPTIONS_ADDED_SINCE = {"symmetry": 0.0, "pose.align": 0, "pose.bones": "video", "fill_unseen": False,
                       "colour_edge": 0.0, "colour.refine": "off", "colour.lr": 0.005, "colour.prior": 0.01,
                       "stage1_resolution": 0, "unmix_background": False}
# Fit options that existed for a while and are gone, none of which changed the fit (``pose.mse`` weighed
# test-time fitting only): a checkpoint whose config.json still has them resumes as if it had not.
OPTIONS_REMOVED = ("pose.mse",)


def _section_of(config: dict, name: str, create: bool = False) -> tuple[dict, str]:
    """The dict of config dict ``config`` that holds the dotted option ``name``, and its key there. A
    missing section is created when ``create``, else read as empty."""
    *sections, key = name.split(".")
    for section in sections:
        config = config.setdefault(section, {}) if create else config.get(section, {})
    return config, key


def _option_missing(saved: dict, name: str) -> bool:
    section, key = _section_of(saved, name)
    return key not in section


def _without_options(config: dict, names) -> dict:
    """A deep copy of the config dict ``config`` without the dotted ``names``."""
    out = json.loads(json.dumps(config))
    for name in names:
        section, key = _section_of(out, name)
        section.pop(key, None)
    return out


def _with_options(config: dict, options: dict) -> dict:
    """A deep copy of the config dict ``config`` with the dotted ``options`` set."""
    out = json.loads(json.dumps(config))
    for name, value in options.items():
        section, key = _section_of(out, name, create=True)
        section[key] = value
    return out


class Trainer:
    """Fits an avatar to a sequence. ``run(resume)`` returns the fitted :class:`Avatar` (also saved).

    Given several sequences, it fits one avatar per sequence — each its own features and body identity —
    with one set of decoders shared by all (the paper's setup); steps take the sequences in turn, and
    ``run`` returns the first avatar. ``self.avatar``, ``self.model``, ``self.frames`` are the first
    sequence's.

    ``finish`` (optional, with ``cfg.fill_unseen``) is called on each fitted avatar before it is saved, as
    ``finish(avatar, body, meshes, mirror=...)`` with ``meshes`` the posed mesh and camera of every training
    frame (:meth:`posed_meshes`), and returns a summary: :class:`gma.edit.unseen.AfterFit`, which records
    what the frames saw and fills the rest (a layer above this one, so the command passes it in)."""

    def __init__(self, cfg: FitConfig, seq, out: str | Path, body=None, ctx=None, progress: bool = True,
                 finish=None):
        from torch import nn

        seqs = list(seq) if isinstance(seq, (list, tuple)) else [seq]
        if not seqs:
            raise ValueError("no sequence to fit")
        self.cfg, self.out = cfg, Path(out)
        self.dir = work_dir(self.out)
        self.body = body or load_body(cfg.avatar.body)
        self.ctx, self.progress, self.finish = ctx, progress, finish
        if cfg.threads:
            torch.set_num_threads(cfg.threads)
        self.subjects: list[Subject] = []
        for i, (s, o) in enumerate(zip(seqs, subject_outputs(self.out, [s.root for s in seqs]), strict=True)):
            frames = load_frames(s, self.body, "train", cfg.resolution, cfg.max_frames)
            if cfg.unmix_background:
                frames.images = unmix_background(frames.images, frames.masks)
            torch.manual_seed(cfg.seed + i)
            avatar = Avatar.create(cfg.avatar, self.body, frames.shape, seed=cfg.seed + i)
            if i > 0:
                avatar.model.share_decoders_with(self.subjects[0].avatar.model)
            self.subjects.append(Subject(o.stem, s, frames, avatar, o))
        first = self.subjects[0]
        self.seq, self.frames, self.avatar, self.model = first.seq, first.frames, first.avatar, first.avatar.model
        self.models = [s.avatar.model for s in self.subjects]
        # What the checkpoint holds and the optimiser walks (shared decoders appear once in parameters()).
        self.avatar_net = self.model if len(self.models) == 1 else nn.ModuleList(self.models)
        self._attach_poses()
        self.frozen_decoders = False
        if cfg.decoders:
            state = load_decoders(cfg.decoders, cfg.avatar)
            unexpected = self.model.load_state_dict(state, strict=False).unexpected_keys
            if unexpected:
                raise ValueError(f"{cfg.decoders}: unexpected decoder tensors {unexpected}")
            self.frozen_decoders = True
        self.stages = [s for s in plan_stages(cfg) if s.steps > 0]
        for sub in self.subjects:
            for res in {cfg.resolution} | {s.resolution for s in self.stages}:
                frames = sub.frames.resized(res)
                weights = colour_weights(frames.masks, cfg.colour_edge) if cfg.colour_edge > 0 else None
                sub.views[res] = (frames, weights)
        self.pose_start = round(cfg.pose.start * self.stages[0].steps) if self.stages else 0
        self.geo = GeometryTerms(self.body.faces, self.body.num_vertices)
        self.symmetry: list[SymmetryPrior | None] = []  # per subject, built by run() once the config is final
        need_lpips = any(s.weights.lpips > 0 for s in self.stages)
        self.lpips = load_lpips(verbose=progress) if need_lpips else None
        self.history: list[dict] = []
        self.timing = {k: 0.0 for k in ("decode", "posing_render_fwd", "render_bwd", "torch_bwd",
                                        "optimizer")}
        self.timed_steps = 0
        self.align_seconds = 0.0  # the pose alignment pass (--pose.align), not a step: kept out of the split

    # -- optimisation set-up ---------------------------------------------------------------------------
    def _optimizer(self, stage: Stage) -> torch.optim.Adam:
        learn = {id(p) for m in self.models for g in stage.groups for p in m.param_groups()[g]}
        feature_ids = None if self.model.direct else {id(p) for m in self.models for p in (m.f_geo, m.f_tex)}
        feats, decs = [], []
        for p in self.avatar_net.parameters():
            on = id(p) in learn
            is_feature = feature_ids is None or id(p) in feature_ids
            if self.frozen_decoders and not is_feature:
                on = False
            p.requires_grad_(on)
            if on:
                (feats if is_feature else decs).append(p)
        param_groups = [{"params": feats, "lr": self.cfg.lr_features, "base_lr": self.cfg.lr_features}]
        if decs:
            param_groups.append({"params": decs, "lr": self.cfg.lr_decoders, "base_lr": self.cfg.lr_decoders})
        if self.pose_sets:  # pose corrections learn in every stage
            pc = self.cfg.pose
            rot = [p for ps in self.pose_sets for p in ps.rotation_params()]
            shift = [p for ps in self.pose_sets for p in ps.translation_params()]
            param_groups += [{"params": rot, "lr": pc.lr_rotation, "base_lr": pc.lr_rotation},
                             {"params": shift, "lr": pc.lr_translation, "base_lr": pc.lr_translation}]
        if self.colour_sets:  # so do the per-frame colour transforms
            lr = self.cfg.colour.lr
            param_groups.append({"params": [p for cs in self.colour_sets for p in cs.parameters()], "lr": lr,
                                 "base_lr": lr})
        return torch.optim.Adam(param_groups, eps=1e-15)

    def _symmetry_prior(self, frames: FrameSet) -> SymmetryPrior | None:
        """The left-right symmetry prior for a subject's frames, or None when it is off or cannot apply:
        the ablation without per-face features, or a body mesh that is not mirror-symmetric (then with a
        notice, as the prior is on by default)."""
        if self.cfg.symmetry == 0 or self.model.direct:
            return None
        try:
            prior = SymmetryPrior(frames, self.body)
        except ValueError as e:
            if self.progress:
                print(f"[gma] symmetry prior skipped: {e}")
            return None
        if self.progress:
            st = prior.summary()
            print(f"[gma] symmetry prior: {100 * st['faces_pulled']:.0f} % of the faces are seen less than "
                  f"{100 * (1 - DEAD_ZONE):.0f} % as much as their mirror and learn from it too (mean weight "
                  f"{st['mean_weight_pulled']:.2f})")
        return prior

    def _bones(self, subject: int, t: int, learn: bool) -> torch.Tensor | None:
        """Bone transforms [J, 4, 4] of training frame ``t`` from its corrected pose (differentiable in
        the correction when ``learn``), or None when the subject's poses are not refined."""
        sub = self.subjects[subject]
        if sub.poses is None:
            return None
        pose = sub.poses.pose(t, detach=not learn)
        return self.body.bone_transforms({"pose": pose, "shape": sub.frames.shape})

    def _locate(self, step: int) -> tuple[int, int]:
        """(stage index, step within the stage) of global ``step``."""
        for i, s in enumerate(self.stages):
            if step < s.steps:
                return i, step
            step -= s.steps
        raise IndexError(step)

    def _frame(self, step: int) -> tuple[int, int]:
        """(subject, training frame) of ``step``: subjects in turn, and per subject a fresh seeded
        permutation of its frames each epoch, so resuming replays the order."""
        k, subject = divmod(step, len(self.subjects))
        n = len(self.subjects[subject].frames)
        epoch, k = divmod(k, n)
        g = torch.Generator().manual_seed(self.cfg.seed * 1_000_003 + epoch + 7_919 * subject)
        return subject, int(torch.randperm(n, generator=g)[k])

    # -- one step --------------------------------------------------------------------------------------
    def _loss(self, stage: Stage, frame: tuple[int, int], timers: dict,
              learn_poses: bool = False) -> tuple[torch.Tensor, dict, dict]:
        w, cfg = stage.weights, self.cfg
        subject, t = frame
        model = self.models[subject]
        frames, weights = self.subjects[subject].view(stage.resolution)
        poses = self.subjects[subject].poses
        t0 = time.perf_counter()
        dec = model.decode(stage.layer)
        bones = self._bones(subject, t, learn_poses)
        t1 = time.perf_counter()
        marks = {}
        out, posed = render_frame(dec, self.body, frames, t, cfg.background, self.ctx, cfg.cull_backfaces,
                                  on_means=lambda g: marks.setdefault("render_bwd_done", time.perf_counter()) and None,
                                  bones=bones)
        t2 = time.perf_counter()
        target = frames.target(t, cfg.background)
        colours = self.subjects[subject].colours
        color = out.color if colours is None else colours.apply(t, out.color, out.alpha, cfg.background)
        l1, dssim = weighted_picture_loss(color, target, None if weights is None else weights[t])
        terms = {"l1": l1, "ssim": dssim, "mask": (out.alpha - frames.masks[t]).abs().mean()}
        if w.lpips > 0 and self.lpips is not None:
            terms["lpips"] = self.lpips(color, target)
        offsets = dec.vertex_offsets
        if w.lap > 0:
            terms["lap"] = self.geo.laplacian(offsets)
        if w.edge > 0:
            terms["edge"] = self.geo.edge(frames.rest[t], offsets)
        if w.offset > 0 and stage.layer == "fine":
            terms["offset"] = (dec.binding.offset / model.d_max).pow(2).mean()
        if w.normal > 0:
            terms["normal"] = normal_consistency(out.normal, out.depth, out.alpha, frames.K[t])
        loss = sum(getattr(w, k) * v for k, v in terms.items())
        if self.symmetry[subject] is not None:  # one weight for both stages: f_tex learns in both
            terms["symmetry"] = self.symmetry[subject](model.f_tex)
            loss = loss + cfg.symmetry * terms["symmetry"]
        if poses is not None and learn_poses:  # its weights are in cfg.pose, not the stage's
            terms["pose_reg"] = poses.regulariser(t, cfg.pose)
            loss = loss + terms["pose_reg"]
        if colours is not None:
            terms["colour_reg"] = colours.regulariser(t)
            loss = loss + cfg.colour.prior * terms["colour_reg"]
        timers["decode"] += t1 - t0
        timers["posing_render_fwd"] += t2 - t1
        rec = {k: float(v.detach()) for k, v in terms.items()}
        rec["psnr"] = psnr(color.detach(), target)
        if len(self.subjects) > 1:
            rec["subject"] = subject
        return loss, rec, marks

    def _aligns_poses(self) -> bool:
        """Whether the fit runs the pose alignment pass: poses refined, ``--pose.align`` > 0, and a stage 1
        to end (the one-stage ablation has none)."""
        return bool(self.pose_sets) and self.cfg.pose.align > 0 and len(self.stages) > 1

    def _align_poses(self, stage: Stage) -> None:
        """Each training frame's pose corrections fitted to its image with the stage's avatar frozen (what
        test-time fitting does): the joint steps move a frame's pose only on the few steps that draw it."""
        t0 = time.perf_counter()
        for model, sub in zip(self.models, self.subjects, strict=True):
            if sub.poses is None:
                continue
            with torch.no_grad():
                decoded = model.decode(stage.layer)
            frames = sub.view(stage.resolution)[0]
            fit_corrections(sub.poses, decoded, self.body, frames, self.cfg.pose.align, self.cfg.pose,
                            self.cfg.background, self.ctx, self.progress, desc="align poses",
                            colour=sub.colours, colour_cfg=self.cfg.colour, cull=self.cfg.cull_backfaces)
        self.align_seconds += time.perf_counter() - t0

    def _preview(self, step: int) -> None:
        with torch.no_grad():
            total = sum(s.steps for s in self.stages)
            layer = self.stages[self._locate(min(step, total) - 1)[0]].layer if step > 0 else self.stages[0].layer
            out, _ = render_frame(self.model.decode(layer), self.body, self.frames, 0, self.cfg.background,
                                  self.ctx, cull=False, bones=self._bones(0, 0, learn=False))
        img = torch.cat([out.color, self.frames.target(0, self.cfg.background)], 1).clamp(0, 1).numpy()
        save_png(self.dir / "previews" / f"step_{step:06d}.png", img)

    # -- after the fit --------------------------------------------------------------------------------
    @torch.no_grad()
    def posed_meshes(self, subject: int):
        """Yields (vertices [V, 3] float32 numpy, Camera) per training frame of ``subject``: the fitted
        avatar's morphed mesh in the frame's (refined) pose, and the camera at the fitting resolution."""
        from gma.body.skinning import linear_blend_skinning
        from gma.core.camera import Camera

        sub = self.subjects[subject]
        offsets = sub.avatar.model.vertex_offsets()
        frames, body = sub.frames, self.body
        h, w = frames.images.shape[1:3]
        for t in range(len(frames)):
            bones = self._bones(subject, t, learn=False)
            bones = frames.bones[t] if bones is None else bones
            verts = linear_blend_skinning(frames.rest[t] + offsets, body.skin_indices, body.skin_weights, bones)
            yield verts.numpy(), Camera(frames.w2c[t].numpy(), frames.K[t].numpy(), int(w), int(h))

    def _finish(self, subject: int) -> None:
        """Run ``finish`` (the seen record and the fill of the unseen faces) on a subject's avatar."""
        if self.finish is None or not self.cfg.fill_unseen or self.model.direct:
            return
        sub = self.subjects[subject]
        self.finish(sub.avatar, self.body, self.posed_meshes(subject), mirror=self.cfg.symmetry > 0)

    # -- the loop --------------------------------------------------------------------------------------
    def _attach_poses(self) -> None:
        """Fresh pose corrections for the subjects whose poses are refined (``cfg.pose``) and colour
        transforms for those whose frames get them (``cfg.colour``), and ``self.net``, what the checkpoint
        holds: the avatar(s), plus the corrections and transforms when there are any."""
        from torch import nn

        bones = BONE_SETS[self.cfg.pose.bones]
        for sub in self.subjects:
            sub.poses = (PoseCorrections(self.body, sub.frames.poses, sub.frames.indices, bones)
                         if refine_wanted(self.cfg.pose, sub.seq) else None)
            sub.colours = FrameColour(len(sub.frames)) if colour_wanted(self.cfg.colour, sub.seq) else None
        self.pose_sets = [s.poses for s in self.subjects if s.poses is not None]
        self.colour_sets = [s.colours for s in self.subjects if s.colours is not None]
        self.net = self.avatar_net
        if self.pose_sets or self.colour_sets:  # checkpoint keys change only for fits that learn these
            parts = {"avatar": self.avatar_net}
            if self.pose_sets:
                parts["poses"] = nn.ModuleList(self.pose_sets)
            if self.colour_sets:
                parts["colours"] = nn.ModuleList(self.colour_sets)
            self.net = nn.ModuleDict(parts)

    def run(self, resume: bool = False) -> Avatar:
        self.dir.mkdir(parents=True, exist_ok=True)
        ckpt = self.dir / CHECKPOINT_NAME
        total = sum(s.steps for s in self.stages)
        step, elapsed, opt = 0, 0.0, None
        if resume and ckpt.is_file():
            opt, step, elapsed = self._resume(ckpt, total)
        elif resume and self.progress:
            print(f"[gma fit] no checkpoint in {self.dir}; starting from step 0")
        self._saved_step = step if step > 0 else None  # the step of the last checkpoint on disk
        atomic_write_json(self.dir / "config.json", self.cfg.to_dict())
        self.symmetry = [self._symmetry_prior(sub.frames) for sub in self.subjects]

        bar = tqdm(total=total, initial=step, desc="fit", unit="step", disable=not self.progress, dynamic_ncols=True)
        stage_idx = self._locate(step)[0] if step < total else len(self.stages) - 1
        if opt is None and step < total:
            opt = self._optimizer(self.stages[stage_idx])
        t_start = time.perf_counter() - elapsed
        while step < total:
            si, local = self._locate(step)
            stage = self.stages[si]
            if si != stage_idx:
                stage_idx, opt = si, self._optimizer(stage)
            try:
                loss_value, rec = self._step(stage, local, step, opt, ckpt)
            except NonFiniteError:
                bar.close()
                raise
            step += 1
            if step % self.cfg.log_every == 0 or step == total:
                self.history.append({"step": step, "stage": stage.name, "loss": loss_value, **rec})
            bar.set_postfix(stage=stage.name[-1], loss=f"{loss_value:.4f}", psnr=f"{rec['psnr']:.1f}")
            bar.update(1)
            stage_end = local + 1 == stage.steps
            if stage_end and si == 0 and self._aligns_poses():
                self._align_poses(stage)
            if step % self.cfg.checkpoint_every == 0 or stage_end:
                next_stage = self._locate(step)[0] if step < total else si
                if next_stage != si:  # the next stage starts with a fresh optimiser
                    opt, stage_idx = self._optimizer(self.stages[next_stage]), next_stage
                try:
                    self._checkpoint(ckpt, opt, step, next_stage, time.perf_counter() - t_start)
                except NonFiniteError as exc:  # a finite loss, but this step's update was not
                    bar.close()
                    raise NonFiniteError(self._diverged_message(f"the parameters are not finite ({exc})", step,
                                                                stage, ckpt)) from None
                self._saved_step = step
            if self.cfg.preview_every and step % self.cfg.preview_every == 0:
                self._preview(step)
        bar.close()
        fit_seconds = time.perf_counter() - t_start
        self._preview(total)
        self._save_avatars(fit_seconds, total)
        self._save_metrics(fit_seconds, total)
        return self.avatar

    def _resume(self, ckpt: Path, total: int):
        """Load the checkpoint after checking that it was made with this config (a fit started before an
        option existed continues as it began). Returns (optimiser, step, elapsed seconds)."""
        cfg_json = self.cfg.to_dict()
        saved = json.loads((self.dir / "config.json").read_text()) if (self.dir / "config.json").is_file() else {}
        saved = _without_options(saved, OPTIONS_REMOVED)
        older = {k: v for k, v in OPTIONS_ADDED_SINCE.items() if saved and _option_missing(saved, k)}
        if older and _with_options(saved, older) == _with_options(cfg_json, older):
            # A fit started before these options existed continues as it began (what they were then).
            saved = _with_options(saved, older)
            self.cfg = FitConfig.from_dict(_with_options(self.cfg.to_dict(), older))
            cfg_json = self.cfg.to_dict()
            self._attach_poses()  # the bone set may be the older one
            if self.progress:
                print(f"[gma fit] this fit started before {', '.join(older)} existed; resuming it with {older}")
        if saved and saved != cfg_json:
            raise ValueError(f"{self.dir / 'config.json'}: the checkpoint was made with another config; "
                             "resume with the same options, or fit without --resume to start over")
        opt, meta = load_checkpoint(ckpt, self.net, lambda m: self._optimizer(self.stages[m["stage"]]))
        self.history = meta["history"]
        self.timing, self.timed_steps = meta["timing"], meta["timed_steps"]
        self.align_seconds = meta.get("align_seconds", 0.0)
        if self.progress:
            print(f"[gma fit] resuming {ckpt} at step {meta['step']}/{total}")
        return opt, meta["step"], meta["elapsed"]

    def _step(self, stage, local: int, step: int, opt, ckpt: Path):
        """One optimisation step of ``stage`` (``local`` steps into it) with the learning rate decayed
        along it; the backward and optimiser times go to ``self.timing``. Returns (loss value, record);
        raises NonFiniteError, before any update, when the loss is not finite."""
        frac = local / max(1, stage.steps)
        for g in opt.param_groups:
            g["lr"] = g["base_lr"] * self.cfg.lr_decay**frac
        loss, rec, marks = self._loss(stage, self._frame(step), self.timing, learn_poses=step >= self.pose_start)
        loss_value = float(loss.detach())
        if not math.isfinite(loss_value):
            raise NonFiniteError(self._diverged_message(f"the loss is {loss_value}", step + 1, stage, ckpt))
        tb = time.perf_counter()
        loss.backward()
        tc = time.perf_counter()
        opt.step()
        opt.zero_grad(set_to_none=True)
        td = time.perf_counter()
        rb = marks.get("render_bwd_done", tc)
        self.timing["render_bwd"] += rb - tb
        self.timing["torch_bwd"] += tc - rb
        self.timing["optimizer"] += td - tc
        self.timed_steps += 1
        return loss_value, rec

    def _diverged_message(self, what: str, step: int, stage: Stage, ckpt: Path) -> str:
        """One line for a fit that diverged (``what``: the loss or the parameters turned NaN or infinite at
        ``step``, counted from 1): where, and what is kept to resume from. The parameters of that step are
        not saved; the checkpoint on disk is from before, and a save never writes non-finite values, so it
        is a good one."""
        kept = (f"the last good checkpoint (step {self._saved_step}) is kept in {ckpt} for --resume"
                if self._saved_step is not None else "no checkpoint was written yet")
        return f"{self.out}: the fit diverged: {what} at step {step} ({stage.name}); {kept}"

    def _checkpoint(self, ckpt: Path, opt, step: int, stage: int, elapsed: float) -> None:
        """Save the weights, ``opt`` (the optimiser of ``stage``, where the fit continues) and progress."""
        meta = {"step": step, "stage": stage, "elapsed": elapsed, "history": self.history,
                "timing": self.timing, "timed_steps": self.timed_steps, "align_seconds": self.align_seconds}
        save_checkpoint(ckpt, self.net, opt, meta)

    def _save_avatars(self, fit_seconds: float, total: int) -> None:
        """Each subject's avatar with what its fit was (and its refined poses), and shared decoders."""
        shared = [s.name for s in self.subjects] if len(self.subjects) > 1 else None
        for i, sub in enumerate(self.subjects):
            mine = [h for h in self.history if h.get("subject", 0) == i]
            sub.avatar.info = {"fit_seconds": round(fit_seconds, 1), "steps": total, "sequence": str(sub.seq.root),
                               "preset": self.cfg.preset, "training": self.cfg.training,
                               "resolution": max(sub.frames.images.shape[1:3]),
                               "final_train_psnr": mine[-1]["psnr"] if mine else None}
            if shared:
                sub.avatar.info["decoders_shared_with"] = shared
            if sub.poses is not None:
                sub.avatar.info["pose_refinement"] = sub.poses.summary()
            if sub.colours is not None:
                sub.avatar.info["frame_colour"] = sub.colours.summary()
            if self.symmetry[i] is not None:
                sub.avatar.info["symmetry_prior"] = self.symmetry[i].summary()
            self._finish(i)
            sub.avatar.save(sub.out)
            if sub.poses is not None:
                save_refined_body(refined_body_path(sub.out), sub.seq, sub.frames.indices, sub.poses.all_poses())
        if shared:
            save_decoders(self.out / "decoders.gma", self.model,
                          {"sequences": [str(s.seq.root) for s in self.subjects], "steps": total})

    def _save_metrics(self, fit_seconds: float, total: int) -> None:
        """metrics.json in the work folder: history, time per step and part, sizes, refinement summaries."""
        shared = [s.name for s in self.subjects] if len(self.subjects) > 1 else None
        n = max(1, self.timed_steps)
        metrics = {"fit_seconds": fit_seconds, "steps": total, "history": self.history,
                   "ms_per_step": {k: 1000 * v / n for k, v in self.timing.items()},
                   "avatar_bytes": sum(s.out.stat().st_size for s in self.subjects) // len(self.subjects),
                   "lpips": self.lpips is not None, "train_frames": sum(len(s.frames) for s in self.subjects),
                   "resolution": list(self.frames.images.shape[1:3])}
        if shared:
            metrics["subjects"] = shared
        if self._aligns_poses():
            metrics["pose_alignment"] = {"steps_per_frame": self.cfg.pose.align, "seconds": self.align_seconds}
        if self.colour_sets:
            metrics["frame_colour"] = {s.name: s.colours.summary() for s in self.subjects if s.colours is not None}
        if self.pose_sets:
            metrics["pose_refinement"] = {s.name: {**s.poses.summary(), "body": str(refined_body_path(s.out))}
                                          for s in self.subjects if s.poses is not None}
        priors = {sub.name: prior.summary() for sub, prior in zip(self.subjects, self.symmetry, strict=True)
                  if prior is not None}
        if priors:
            metrics["symmetry_prior"] = priors
        unseen = {sub.name: sub.avatar.info["unseen"] for sub in self.subjects if "unseen" in sub.avatar.info}
        if unseen:
            metrics["unseen"] = unseen
        atomic_write_json(self.dir / "metrics.json", metrics)
