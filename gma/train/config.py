"""Fitting configuration as dataclasses (the CLI is built from them, see ``gma.commands._options``),
and the quick / full presets."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import asdict, dataclass, fields

from gma.avatar.config import AvatarConfig, doc

__all__ = ["PRESETS", "FitConfig", "FrameColourConfig", "LossWeights", "PoseRefineConfig", "preset"]

TRAINING_MODES = ("two_stage", "one_stage")
REFINE_MODES = ("auto", "on", "off")
# Which bones pose refinement corrects (gma.train.pose_refine.BONE_SETS holds the names).
BONE_SET_NAMES = ("body", "video")


def _float_options(config, prefix: str = ""):
    """(command-line option, value) of every float field of ``config``, nested dataclasses included."""
    for f in fields(config):
        value = getattr(config, f.name)
        if dataclasses.is_dataclass(value):
            yield from _float_options(value, f"{prefix}{f.name}.")
        elif isinstance(value, float):
            yield f"--{prefix}{f.name}".replace("_", "-"), value


@dataclass
class LossWeights:
    """Weights of one stage's loss terms (picture: L1, SSIM, mask, LPIPS; geometry: Laplacian, relative
    edge, 2DGS normal consistency). Defaults are the paper's stage 1, except edge (see its note)."""

    l1: float = doc(0.8, "L1 colour loss")
    ssim: float = doc(0.2, "1 - SSIM (gaussian window 11, sigma 1.5)")
    mask: float = doc(0.1, "L1 between rendered alpha and the person mask (removes floating surfels)")
    lpips: float = doc(0.0, "LPIPS (only when its weights are installed locally; else skipped)")
    lap: float = doc(1000.0, "Laplacian of the mesh-layer displacement (mean squared norm)")
    edge: float = doc(0.3, "relative edge-length change, morphed vs body mesh (mean squared). The paper's 100 "
                           "flattens the normal-offset mesh layer: an offset d on a surface of curvature k "
                           "stretches its edges by d*k, so the ground-truth clothing of the demo sequence "
                           "costs 0.31 (x100 = 31, vs a picture loss of ~0.03) and stage 1 learnt 0.07 mm "
                           "offsets. 0.3 fit the clothing best in a stage-1 sweep over 0, 0.3, 1, 10, 100")
    normal: float = doc(0.05, "2DGS normal consistency: rendered normals vs normals of the rendered depth")
    offset: float = doc(0.01, "mean (d / d_max)^2 of the fine surfels' normal offsets (fine layer "
                              "only): keeps surfels on the morphed mesh. Without it Adam, which normalises a "
                              "tiny but biased gradient, drove d to -1 cm on most surfels: the skin sank "
                              "below the inner eye/mouth cavities, which then showed through the face")


@dataclass
class PoseRefineConfig:
    """Per-frame pose corrections learnt with the avatar (``--pose.*``)."""

    refine: str = doc("auto", "auto (on for sequences from 'gma import video', whose poses are estimated), "
                              "on, or off (trusted poses)")
    lr_rotation: float = doc(0.01, "Adam learning rate of the bone rotation corrections (radians)")
    lr_translation: float = doc(0.005, "Adam learning rate of the root translation corrections (metres)")
    prior: float = doc(0.01, "pull of the corrections toward the input poses: weight of the mean squared "
                             "rotation correction (rad^2, mean over bones) and root shift (per 30 cm)^2")
    smooth: float = doc(0.1, "smoothness: weight of the squared difference between the corrections of "
                             "frames adjacent in the sequence")
    start: float = doc(0.25, "fraction of stage 1 before the poses start learning (the avatar first gets "
                             "a rough shape and colour to align against)")
    align: int = doc(30, "steps per training frame of a pose alignment pass at the end of stage 1: each "
                         "frame's corrections fitted to its image with the avatar frozen, as at evaluation (0: off)")
    bones: str = doc("body", "which bones are corrected: body (36: the video fit's 23 plus the arm and leg "
                             "twist bones, shoulders, hips and the upper neck) or video (the 23 the video "
                             "fit estimates)")

    def __post_init__(self):
        if self.refine not in REFINE_MODES:
            raise ValueError(f"--pose.refine: expected one of {REFINE_MODES}, got {self.refine!r}")
        if self.align < 0:
            raise ValueError(f"--pose.align: expected a number of steps >= 0, got {self.align}")
        if self.bones not in BONE_SET_NAMES:
            raise ValueError(f"--pose.bones: expected one of {BONE_SET_NAMES}, got {self.bones!r}")


@dataclass
class FrameColourConfig:
    """Per-frame colour transforms learnt with the avatar (``--colour.*``, gma.train.appearance)."""

    refine: str = doc("auto", "auto (on for sequences from 'gma import video': a phone changes exposure and white "
                              "balance while filming), on, or off. A gain and an offset per channel and frame, "
                              "discarded with the fit; held-out frames get theirs at test-time pose fitting")
    lr: float = doc(0.005, "Adam learning rate of the gains and offsets")
    prior: float = doc(0.01, "pull toward identity: weight of the squared gains and offsets")

    def __post_init__(self):
        if self.refine not in REFINE_MODES:
            raise ValueError(f"--colour.refine: expected one of {REFINE_MODES}, got {self.refine!r}")


def _stage2_weights() -> LossWeights:
    return LossWeights(lap=100.0, edge=10.0, normal=0.0, lpips=0.02)


@dataclass
class FitConfig:
    """Everything ``gma fit`` does; saved (resolved) as ``config.json`` in the fit's work folder."""

    preset: str = doc("quick", "quick (a CPU, minutes: demos and tests), standard (a CPU, half an hour: real "
                               "video; gma fit's choice for sequences from gma import video) or full (a GPU); "
                               "other options override it")
    seed: int = doc(0, "seeds the avatar init and the frame order: same seed, same result")
    training: str = doc("two_stage", "two_stage (paper) or one_stage (ablation: all at once)")
    stage1_steps: int = doc(80, "steps of stage 1 (geometry: coarse surfels, mesh layer)")
    stage2_steps: int = doc(160, "steps of stage 2 (texture: fine surfels; F_coarse, f_geo frozen)")
    resolution: int = doc(128, "longest image side the fit renders at (images are area-downsampled)")
    stage1_resolution: int = doc(0, "longest image side of stage 1 and the pose alignment pass: geometry and poses "
                                    "at a low resolution, texture at --resolution (0, or above --resolution: "
                                    "--resolution)")
    max_frames: int = doc(0, "use at most this many training frames, evenly spaced (0: all)")
    lr_features: float = doc(0.05, "Adam learning rate of f_geo, f_tex (and free params of 'direct')")
    lr_decoders: float = doc(0.005, "Adam learning rate of the decoder MLPs")
    symmetry: float = doc(1.0, "left-right symmetry prior (0: off): pulls the texture features of each face "
                               "toward its mirror face's, in proportion to how much less the training frames "
                               "show it than its mirror (gma.train.symmetry). Acts only where a clip shows one "
                               "side of the person less than the other (none on the built-in synthetic "
                               "sequences); on a real turn that stops short of the start, +0.5 dB on the "
                               "unseen views. Skipped, with a notice, for body meshes that are not symmetric")
    fill_unseen: bool = doc(True, "after the fit, record how well the frames saw each face (saved in the avatar) and "
                                  "give the faces no frame saw colours filled from the seen ones (gma.avatar.fill): "
                                  "the back of a person filmed from the front. Where the caller provides the step "
                                  "(gma fit, gma demo)")
    lr_decay: float = doc(0.1, "learning rates fall exponentially to this fraction by each stage's end")
    background: float = doc(0.5, "grey level behind the person (targets are composited over it)")
    unmix_background: bool = doc(False, "take the real background's colour out of the person mask's soft edge "
                                         "pixels before compositing the targets over --background: a green screen's "
                                         "green, a wall's white (estimated per frame from the pixels around; "
                                         "gma.train.appearance.unmix_background)")
    colour_edge: float = doc(0.0, "pixels over which the colour loss's weight rises from 0 at the person mask's "
                                  "boundary to 1 inside; outside the mask it is 0, so a surfel straying there "
                                  "learns no background colour and the mask loss alone keeps the outline "
                                  "(0: the colour loss over the whole image)")
    cull_backfaces: bool = doc(True, "skip surfels on faces turned away from the camera (about half the surfels)")
    threads: int = doc(1, "torch CPU threads (0: torch's default). 1 is the safe choice on a small or shared CPU: "
                            "more threads are faster on idle cores but slower beside other busy processes, as "
                            "torch's threads wait for each other's cores")
    decoders: str = doc("", "frozen shared decoders (a decoders.gma from a several-sequence fit, or any .gma "
                            "avatar): fit only the features")
    checkpoint_every: int = doc(50, "steps between atomic checkpoints (also at each stage's end)")
    log_every: int = doc(10, "steps between loss records in metrics.json")
    preview_every: int = doc(100, "steps between preview renders (0: only at the end)")
    weights1: LossWeights = dataclasses.field(default_factory=LossWeights,
                                              metadata={"doc": "stage 1 loss weights"})
    weights2: LossWeights = dataclasses.field(default_factory=_stage2_weights,
                                              metadata={"doc": "stage 2 loss weights"})
    avatar: AvatarConfig = dataclasses.field(default_factory=AvatarConfig,
                                             metadata={"doc": "the representation"})
    pose: PoseRefineConfig = dataclasses.field(default_factory=PoseRefineConfig,
                                               metadata={"doc": "per-frame pose corrections"})
    colour: FrameColourConfig = dataclasses.field(default_factory=FrameColourConfig,
                                                  metadata={"doc": "per-frame colour transforms"})

    def __post_init__(self):
        if self.training not in TRAINING_MODES:
            raise ValueError(f"training must be one of {TRAINING_MODES}, got {self.training!r}")
        if not self.symmetry >= 0:
            raise ValueError(f"symmetry must be >= 0, got {self.symmetry}")
        if self.stage1_steps < 0 or self.stage2_steps < 0 or self.resolution < 8:
            raise ValueError("steps must be >= 0 and resolution >= 8")
        if self.stage1_resolution != 0 and self.stage1_resolution < 8:
            raise ValueError(f"--stage1-resolution: expected 0 (as --resolution) or >= 8, got {self.stage1_resolution}")
        for option, value in _float_options(self):
            # Rates, weights, sizes and fractions, all >= 0: a NaN would only show as a diverged fit.
            if not (math.isfinite(value) and value >= 0):
                raise ValueError(f"{option}: must be a finite number >= 0, got {value}")

    @property
    def total_steps(self) -> int:
        return self.stage1_steps + self.stage2_steps

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict) -> FitConfig:
        d = dict(d)
        for name, cls in (("weights1", LossWeights), ("weights2", LossWeights), ("avatar", AvatarConfig),
                          ("pose", PoseRefineConfig), ("colour", FrameColourConfig)):
            if name in d and isinstance(d[name], dict):
                d[name] = cls(**d[name])
        known = {f.name for f in fields(FitConfig)}
        if set(d) - known:
            raise ValueError(f"unknown fit config keys {sorted(set(d) - known)}")
        return FitConfig(**d)


# Preset = overrides of the defaults. quick: fits within minutes on a small CPU through lavapipe
# (few, small renders; 2 fine surfels per face); standard: an avatar from a phone video on a CPU, shown
# at 384 px and more: geometry and poses at 192 px, the texture at 384 px, the real background unmixed
# from the mask's soft edge (docs/fitting.md#the-standard-preset); full: the paper-like setting for a real GPU.
PRESETS: dict[str, dict] = {
    "quick": {"stage1_steps": 200, "stage2_steps": 400, "resolution": 192, "preview_every": 200,
              "avatar": {"fine_per_face": 2, "feature_dim": 16}},
    "standard": {"stage1_steps": 200, "stage2_steps": 400, "resolution": 384, "stage1_resolution": 192,
                 "unmix_background": True, "preview_every": 200, "pose": {"align": 15},
                 "avatar": {"fine_per_face": 2, "feature_dim": 16}},
    "full": {"stage1_steps": 3000, "stage2_steps": 5000, "resolution": 512, "checkpoint_every": 500,
             "log_every": 50, "preview_every": 1000, "lr_decay": 0.05,
             "avatar": {"fine_per_face": 4, "feature_dim": 32}},
}


def preset(name: str, **overrides) -> FitConfig:
    """The preset ``name`` with ``overrides`` (nested dicts for ``avatar``/``weights1``/``weights2``)."""
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; choose one of {sorted(PRESETS)}")
    d = FitConfig().to_dict()
    for src in (PRESETS[name], overrides):
        for k, v in src.items():
            if isinstance(v, dict):
                d[k] = {**d[k], **v}
            else:
                d[k] = v
    d["preset"] = name
    return FitConfig.from_dict(d)
