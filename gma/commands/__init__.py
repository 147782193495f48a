"""Subcommands of ``gma``: one module each, with ``register(subparsers)`` and a ``run`` behind it.

Commands import the heavy layers (torch, wgpu, the body model) inside ``run``, not at module level:
``gma --help`` and argument errors must answer in well under a second, before any of them loads."""
