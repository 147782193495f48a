"""Subcommands of ``gma``: one module each, with ``register(subparsers)``."""
