"""``gma view SOURCE``: the real-time viewer window (same options as ``gma-viewer``)."""

from __future__ import annotations

import argparse


def register(subparsers) -> None:
    from viewer.app import add_arguments

    p = subparsers.add_parser("view", help="open an avatar, a splat PLY or the body in the real-time viewer")
    add_arguments(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    from viewer.app import run as run_viewer

    return run_viewer(args)
