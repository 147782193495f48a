"""What the window and the panels share: the tool names a left drag or click can use, and how a tool
action's user error becomes the status line (instead of an exception out of a glfw callback)."""

from __future__ import annotations

from gma.core.errors import GmaError

__all__ = ["TOOLS", "report"]

# Tools a left drag / click uses (the window maps a key to each, the Edit panel lists them).
TOOLS = ("navigate", "box", "lasso", "brush", "wand", "paint", "eyedropper", "stamp")


def report(state, fn, *args, **kwargs):
    """Run a tool action; a user error (GmaError, OSError, ValueError) becomes ``state.message`` (its first
    line) and the call returns None."""
    try:
        return fn(*args, **kwargs)
    except (GmaError, OSError, ValueError) as exc:
        state.message = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        return None
