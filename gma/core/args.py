"""Argument types shared by the command line and the viewer (argparse ``type=`` callables)."""

from __future__ import annotations

import argparse
import math
import re

__all__ = ["parse_image_size", "non_negative_float", "non_negative_int", "positive_float", "positive_int"]


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



def _number(kind: type, low: float, low_ok: bool, what: str):
    """An argparse ``type`` for a finite ``kind`` (int or float) above ``low`` (or equal, with ``low_ok``)."""

    def parse(text: str):
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'a whole number' if kind is int else 'a number'}, "
                                             f"got {text!r}") from None
        if not math.isfinite(value) or value < low or (value == low and not low_ok):
            raise argparse.ArgumentTypeError(f"must be {what}, got {text}")
        return value

    parse.__name__ = f"{kind.__name__}_{'from' if low_ok else 'above'}_{low:g}"
    return parse


positive_int = _number(int, 1, True, "at least 1")
non_negative_int = _number(int, 0, True, "at least 0")
positive_float = _number(float, 0.0, False, "a finite number above 0")
non_negative_float = _number(float, 0.0, True, "a finite number of at least 0")
