"""Shared decoders: the four MLPs (F_coarse, F_fine, T_color, T_scale) without any avatar's features.

The paper trains the decoders over several subjects, then fits a new identity by optimising only its
per-face features against the frozen decoders. ``gma fit SEQ1 SEQ2 ... -o DIR`` writes
``DIR/decoders.gma`` in this format; ``gma fit SEQ --decoders FILE`` reads it (or any ``.gma`` avatar,
whose decoders it takes).

File layout (safetensors, never pickle; written atomically):

    tensors   decoder.*   the decoder weights (``AvatarModel.decoder_state()``)
    metadata  format = "gma-decoders", version = "1", body = model id, config = AvatarConfig JSON,
              info = JSON dict (which sequences trained them)
"""

from __future__ import annotations

import json
import os
from pathlib import Path

import torch
from safetensors.torch import save

from gma.avatar.avatar import AVATAR_FORMAT, FORMAT_VERSION, AvatarFileError, read_tagged_file
from gma.avatar.config import AvatarConfig
from gma.avatar.model import AvatarModel
from gma.core.atomic import atomic_write_bytes
from gma.core.checks import require_finite
from gma.core.errors import NonFiniteError

__all__ = ["ARCHITECTURE_FIELDS", "load_decoders", "save_decoders"]

DECODERS_FORMAT = "gma-decoders"
DECODERS_VERSION = 1
# The config fields that fix the decoders' input and output sizes and meaning: two configs must agree on
# these for one's decoders to serve the other's features.
ARCHITECTURE_FIELDS = ("body", "representation", "feature_dim", "hidden", "pe_freqs", "fine_per_face")


def save_decoders(path: str | os.PathLike, model: AvatarModel, info: dict | None = None) -> Path:
    """Write the decoders of ``model`` to ``path`` atomically; returns the path."""
    if model.direct:
        raise ValueError("the 'direct' representation has no decoders to share")
    tensors = {f"decoder.{k}": v.detach().contiguous().cpu() for k, v in model.decoder_state().items()}
    meta = {"format": DECODERS_FORMAT, "version": str(DECODERS_VERSION), "body": model.config.body,
            "config": json.dumps(model.config.to_dict()), "info": json.dumps(info or {})}
    path = Path(path)
    require_finite(tensors, f"{path}: not written", NonFiniteError)
    atomic_write_bytes(path, save(tensors, metadata=meta))
    return path


def load_decoders(path: str | os.PathLike, config: AvatarConfig) -> dict[str, torch.Tensor]:
    """The decoder weights in ``path`` (a decoders file or a ``.gma`` avatar), checked against ``config``:
    a file whose decoders were built for other feature sizes, widths or surfel counts is refused with a
    message that names the file and the fields that differ."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: decoders file not found")
    tensors, meta = read_tagged_file(path, {DECODERS_FORMAT: DECODERS_VERSION, AVATAR_FORMAT: FORMAT_VERSION},
                                     "a decoders file or a .gma avatar")
    prefix = "decoder." if meta["format"] == DECODERS_FORMAT else "model."
    try:
        theirs = AvatarConfig.from_dict(json.loads(meta["config"]))
    except (KeyError, ValueError, TypeError) as exc:
        raise AvatarFileError(f"{path}: bad config metadata ({exc})") from exc
    if theirs.representation == "direct":
        raise AvatarFileError(f"{path}: a 'direct' avatar has no decoders")
    differ = [f"{k} {getattr(theirs, k)!r} vs {getattr(config, k)!r}" for k in ARCHITECTURE_FIELDS
              if getattr(theirs, k) != getattr(config, k)]
    if differ:
        raise AvatarFileError(f"{path}: its decoders do not fit this avatar config ({'; '.join(differ)})")
    state = {k[len(prefix):]: v for k, v in tensors.items()
             if k.startswith(prefix) and not k[len(prefix):].startswith(("f_geo", "f_tex"))}
    if not state:
        raise AvatarFileError(f"{path}: holds no decoder weights")
    return state
