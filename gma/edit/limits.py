"""The ranges an edit's numbers must lie in, in one table: the library checks them, and the command
line and the viewer refuse the same values in the same words (one line naming the value and its range).

NaN and infinity are refused everywhere; the upper bounds are far beyond any useful edit and keep a
slip of the keyboard (``--size 1e9m``) from becoming an avatar.
"""

from __future__ import annotations

import math

from gma.core.checks import require_in_range
from gma.edit.errors import EditError

__all__ = ["MAX_COLOR_TOLERANCE", "MAX_RINGS", "MAX_ROTATION_DEG", "MAX_SCREEN_PIXELS", "MAX_STAMP_METRES",
           "MAX_TEX_TOLERANCE", "VIEW_SIZE", "check_number", "check_pixel"]

# A stamp larger than a person covers the whole body from any view: a few metres is the most that means
# anything (the size is the image's longer side, on the body at the centre's depth).
MAX_STAMP_METRES = 4.0
# Stamp sizes and brush radii in pixels: the largest texture side GPUs take, far beyond any view.
MAX_SCREEN_PIXELS = 16384.0
# Rotations in degrees: one turn either way (larger values only wrap around).
MAX_ROTATION_DEG = 360.0
# Magic-wand tolerances: by colour, the largest RGB distance in the unit cube (everything connected);
# by f_tex, a distance relative to the median feature norm.
MAX_COLOR_TOLERANCE = math.sqrt(3.0)
MAX_TEX_TOLERANCE = 10.0
# Rings of faces a selection grows or shrinks by at once (a handful of rings crosses a limb).
MAX_RINGS = 100
# Side of the named views screen-space tools work in (pixels).
VIEW_SIZE = (16, 4096)


def check_number(name: str, value, low: float, high: float, unit: str = "", low_open: bool = False) -> float:
    """``value`` as a float if it is finite and in [low, high] (``(low, high]`` with ``low_open``), else
    EditError naming ``name``, the range and the value."""
    return require_in_range(name, value, low, high, unit, low_open, error=EditError)


def check_pixel(name: str, xy) -> tuple[float, ...]:
    """Pixel coordinates as floats when every one is a finite number (outside the image is allowed: it
    shows no face), else EditError naming ``name``."""
    try:
        values = tuple(float(v) for v in xy)
    except (TypeError, ValueError):
        raise EditError(f"{name}: pixel coordinates must be numbers, got {xy!r}") from None
    if not all(math.isfinite(v) for v in values):
        raise EditError(f"{name}: pixel coordinates must be finite numbers, got {list(values)}")
    return values
