"""One family of errors for everything a user can get wrong.

Every error that a user's input can cause (a bad file, a bad argument, an output that cannot be
written, a device that cannot do what was asked) is a :class:`GmaError`. Its message is one line that
names the file or argument and the problem; the command line and the viewer print it as
``gma CMD: error: MESSAGE`` and exit with code 2. Anything else is a bug in GMA and keeps its traceback.

The subclasses also derive from the matching built-in type (``ValueError``, ``FileNotFoundError``, ...)
so that library callers that catch those keep working.
"""

from __future__ import annotations

__all__ = ["DeviceError", "GmaError", "InputError", "MissingFileError", "NonFiniteError", "OutputError",
           "OutputExistsError"]


class GmaError(Exception):
    """Base class: a problem with what the user asked for, reported as one line (exit code 2)."""


class InputError(GmaError, ValueError):
    """An input file or argument that cannot be used (the message names it and says why)."""


class MissingFileError(GmaError, FileNotFoundError):
    """A file or folder the user named does not exist."""


class OutputError(GmaError, OSError):
    """An output that cannot or may not be written (exists without --force, not writable, a folder)."""


class OutputExistsError(OutputError, FileExistsError):
    """An output that exists, where replacing it was not asked for."""


class NonFiniteError(GmaError, ValueError):
    """NaN or infinite values where a result must be finite: an avatar or checkpoint about to be saved, a
    fit whose loss diverged. Nothing is written."""


class DeviceError(GmaError, RuntimeError):
    """The GPU adapter cannot do what was asked (no adapter, a size over its limits)."""
