"""Fitting an avatar to a sequence: configuration, losses, metrics, the two-stage trainer, evaluation."""

from gma.train.config import PRESETS, FitConfig, LossWeights, preset
from gma.train.metrics import psnr, ssim

__all__ = ["PRESETS", "FitConfig", "LossWeights", "preset", "psnr", "ssim"]
