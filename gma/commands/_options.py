"""Build argparse options from config dataclasses, and turn parsed options back into overrides.

Fields become ``--name`` (underscores as dashes); nested dataclass fields become ``--parent.name``
(e.g. ``--weights2.lpips 0``, ``--avatar.fine-per-face 4``). Options default to "not given", so a
preset supplies every value the user did not set."""

from __future__ import annotations

import argparse
import dataclasses

__all__ = ["add_dataclass_options", "collect_overrides"]


def _parse_bool(text: str) -> bool:
    if text.lower() in ("1", "true", "yes", "on"):
        return True
    if text.lower() in ("0", "false", "no", "off"):
        return False
    raise argparse.ArgumentTypeError(f"expected true/false, got {text!r}")


def add_dataclass_options(parser: argparse.ArgumentParser, cls, prefix: str = "", skip=()) -> None:
    """Add one option per field of dataclass ``cls`` (recursing into nested dataclasses)."""
    inst = cls()
    for f in dataclasses.fields(cls):
        if f.name in skip:
            continue
        value = getattr(inst, f.name)
        name = prefix + f.name
        if dataclasses.is_dataclass(value):
            add_dataclass_options(parser, type(value), prefix=name + ".")
            continue
        typ = _parse_bool if isinstance(value, bool) else type(value)
        # SUPPRESS: an option not given leaves no attribute (so the preset decides), and help formatters
        # that print defaults leave it alone (the help text states the dataclass default).
        parser.add_argument("--" + name.replace("_", "-"), dest="cfg:" + name, type=typ, default=argparse.SUPPRESS,
                            metavar=type(value).__name__.upper(),
                            help=f"{f.metadata.get('doc', '')} (default {value!r})")


def collect_overrides(args: argparse.Namespace) -> dict:
    """Nested dict of the options the user actually gave."""
    out: dict = {}
    for key, value in vars(args).items():
        if not key.startswith("cfg:") or value is None:
            continue
        parts = key[4:].split(".")
        d = out
        for p in parts[:-1]:
            d = d.setdefault(p, {})
        d[parts[-1]] = value
    return out
