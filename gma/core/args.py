"""Argument types shared by the command line and the viewer (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse
import re

__all__ = ["parse_image_size"]


def parse_image_size(text: str) -> tuple[int, int]:
    """``--size`` for every command: ``N`` (square) or ``WxH``, positive. An argparse ``type``."""
    m = re.fullmatch(r"(\d+)(?:[xX](\d+))?", text.strip())
    if not m:
        raise argparse.ArgumentTypeError(f"size must be N or WxH (e.g. 800x600), got {text!r}")
    w = int(m.group(1))
    h = int(m.group(2) or w)
    if w < 1 or h < 1:
        raise argparse.ArgumentTypeError(f"size must be positive, got {text!r}")
    return w, h
