"""How the command line and the viewer turn errors into one line and an exit code."""

from __future__ import annotations

import sys

from gma.core.errors import GmaError

__all__ = ["EXIT_USAGE", "run_reporting_errors"]

EXIT_USAGE = 2  # bad input, as argparse's own usage errors

# Built-in errors that user input still raises in places not yet converted to GmaError (a missing file
# opened by a library, a value check in a loader). They name the file in their message too.
_USER_ERRORS = (GmaError, FileNotFoundError, PermissionError, IsADirectoryError, NotADirectoryError,
                FileExistsError, ValueError)


def run_reporting_errors(fn, prog: str, debug: bool = False) -> int:
    """Call ``fn()`` and return its exit code; a user error prints ``PROG: error: MESSAGE`` on one line and
    returns 2. With ``debug`` every error keeps its traceback; anything not a user error is a bug in GMA
    and keeps it anyway."""
    try:
        return int(fn() or 0)
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    except _USER_ERRORS as exc:
        if debug:
            raise
        message = " ".join(str(exc).split()) or type(exc).__name__
        print(f"{prog}: error: {message}", file=sys.stderr)
        return EXIT_USAGE
