"""The ``gma`` command. Each subcommand lives in its own module under ``gma/commands/`` and exposes
``register(subparsers)``; this file only discovers and dispatches them, so adding a command never
means editing a shared list."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

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


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    if not getattr(args, "func", None):
        parser.print_help()
        return 2
    # User errors (bad files, bad arguments, outputs that cannot be written) print one clear line.
    return run_reporting_errors(lambda: args.func(args), f"gma {args.command}", args.debug)

if __name__ == "__main__":
    sys.exit(main())
