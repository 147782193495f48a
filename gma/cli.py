"""The ``gma`` command. Each subcommand lives in its own module under ``gma/commands/`` and exposes
``register(subparsers)``; this file only discovers and dispatches them, so adding a command never
means editing a shared list."""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys
import tempfile

import gma.commands
from gma.core.report import run_reporting_errors


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gma", description="Gaussian Morphing Avatars")
    parser.add_argument("--debug", action="store_true", help="show the traceback of every error")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(gma.commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):  # helpers of the commands (option builders, the demo's stages)
            continue
        module = importlib.import_module(f"gma.commands.{info.name}")
        if hasattr(module, "register"):
            module.register(sub)
    return parser


def prepare_environment(environ=os.environ) -> None:
    """The command's process environment, set up before any library runs (the library itself never
    writes the environment). Mesa's Vulkan drivers print "XDG_RUNTIME_DIR is invalid" on every start
    without a private runtime folder (containers, CI, cron): give them one when the session has none, one
    per user and reused by every run (the Makefile's choice too), private as the XDG spec asks."""
    current = environ.get("XDG_RUNTIME_DIR")
    if current and os.path.isdir(current) and os.access(current, os.W_OK):
        return
    user = os.getuid() if hasattr(os, "getuid") else 0
    folder = os.path.join(tempfile.gettempdir(), f"gma-xdg-{user}")
    try:
        os.makedirs(folder, mode=0o700, exist_ok=True)
    except OSError:   # (a read-only temp folder: Mesa's warning is all that is lost)
        return
    environ["XDG_RUNTIME_DIR"] = folder


def main(argv: list[str] | None = None) -> int:
    prepare_environment()
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    # User errors (bad files, bad arguments, outputs that cannot be written) print one clear line.
    return run_reporting_errors(lambda: args.func(args), f"gma {args.command}", args.debug)

if __name__ == "__main__":
    sys.exit(main())
