"""The ``gma`` command. Each subcommand lives in its own module under ``gma/commands/`` and exposes
``register(subparsers)``; this file only discovers and dispatches them, so adding a command never
means editing a shared list."""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys

import gma.commands


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="gma", description="Gaussian Morphing Avatars")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for info in sorted(pkgutil.iter_modules(gma.commands.__path__), key=lambda m: m.name):
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
    try:
        return int(args.func(args) or 0)
    except (FileNotFoundError, ValueError) as exc:
        # User-facing errors (bad files, bad arguments) print one clear line instead of a traceback.
        print(f"gma {args.command}: error: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
