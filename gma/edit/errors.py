"""The error every edit raises for bad input: one line that names what is wrong (a GmaError, so the
command line and the viewer print it without a traceback)."""

from __future__ import annotations

from gma.core.errors import InputError

__all__ = ["EditError"]


class EditError(InputError):
    """An edit that cannot be done as asked (unknown region, empty selection, bad colour, unreadable
    image, donor with other decoders, camera that sees nothing, nothing to undo, ...)."""
