"""The error every edit raises for bad input: one line that names what is wrong (a ValueError, so the
CLI prints it without a traceback)."""

from __future__ import annotations

__all__ = ["EditError"]


class EditError(ValueError):
    """An edit that cannot be done as asked (unknown region, empty selection, bad colour, unreadable
    image, donor with other decoders, camera that sees nothing, nothing to undo, ...)."""
