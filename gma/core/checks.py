"""Checks that numbers can be used: finite (no NaN, no infinity) and inside a stated range.

One place for them, so that every reader and writer says the same thing in the same words: a file
whose tensors hold NaN is refused with ``avatar.gma: f_tex holds 812 NaN values``, an option out of
range with ``--size 1e9m: must lie in (0, 4] m``. Arrays may be numpy arrays, torch tensors or
anything ``numpy.asarray`` takes; integer arrays are finite by construction and cost nothing.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from gma.core.errors import InputError

__all__ = ["non_finite_problem", "require_finite", "require_in_range"]


def _counts(values) -> tuple[int, int]:
    """(NaN count, infinity count) of ``values``."""
    if hasattr(values, "detach"):  # a torch tensor: counted by torch, so bfloat16 and GPU tensors work
        if not values.is_floating_point():
            return 0, 0
        v = values.detach()
        return int(v.isnan().sum()), int(v.isinf().sum())
    a = np.asarray(values)
    if not np.issubdtype(a.dtype, np.inexact):
        return 0, 0
    return int(np.isnan(a).sum()), int(np.isinf(a).sum())


def non_finite_problem(values) -> str | None:
    """What is not finite in ``values``, in words (``"812 NaN values"``, ``"1 infinite value"``,
    ``"2 NaN and 3 infinite values"``), or None when every value is finite."""
    nan, inf = _counts(values)
    if not nan and not inf:
        return None
    parts = [f"{nan} NaN" if nan else "", f"{inf} infinite" if inf else ""]
    return " and ".join(p for p in parts if p) + (" value" if nan + inf == 1 else " values")


def require_finite(named: Mapping[str, object], where: str, error: type[Exception] = InputError) -> None:
    """Raise ``error`` naming ``where`` and the first entry of ``named`` (name -> array) that holds a NaN
    or an infinity, e.g. ``avatar.gma: f_tex holds 812 NaN values``."""
    for name, values in named.items():
        problem = non_finite_problem(values)
        if problem is not None:
            raise error(f"{where}: {name} holds {problem}")


def require_in_range(name: str, value: float, low: float, high: float, unit: str = "",
                     low_open: bool = False, error: type[Exception] = InputError) -> float:
    """``value`` as a float when it is finite and in [low, high] (``(low, high]`` with ``low_open``);
    otherwise ``error`` naming ``name``, the range and the value (``--rotation: must lie in [-360, 360]
    degrees, got 1e+09``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise error(f"{name}: must be a number, got {value!r}") from None
    too_low = v <= low if low_open else v < low
    if not math.isfinite(v) or too_low or v > high:
        bracket = "(" if low_open else "["
        raise error(f"{name}: must lie in {bracket}{low:g}, {high:g}]{' ' + unit if unit else ''}, got {v:g}")
    return v
