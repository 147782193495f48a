"""Fitting an avatar to a sequence: configuration, losses, metrics, the two-stage trainer, evaluation."""

import importlib

# Exports load on first use (PEP 562): ``gma --help`` reads the config dataclasses without torch.
_EXPORTS = {"PRESETS": "gma.train.config", "FitConfig": "gma.train.config", "LossWeights": "gma.train.config",
            "preset": "gma.train.config", "psnr": "gma.train.metrics", "ssim": "gma.train.metrics"}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    if name in _EXPORTS:
        return getattr(importlib.import_module(_EXPORTS[name]), name)
    raise AttributeError(f"module 'gma.train' has no attribute {name!r}")
