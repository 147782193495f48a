"""``Avatar``: a fitted GMA (model + body identity + edit history) and its ``.gma`` file.

File layout (one safetensors file; never pickle, so opening a stranger's avatar runs no code):

    tensors   model.*            features and decoder weights (``AvatarModel.state_dict()``)
              rest_vertices      [V, 3] canonical body vertices at the identity shape (positional encoding
                                 and offset directions are derived from these, so decoding is reproducible)
              shape              [S] body identity (Anny phenotype / SMPL-X betas)
    metadata  format = "gma", version = "1", body = model id, config = AvatarConfig JSON,
              history = JSON list of edit records, info = JSON dict (fit summary, free-form)

Writes are atomic (temporary file, fsync, rename). A file from a newer format version is refused with
a message that names the file and both versions. Every tensor is finite both ways: a file holding a
NaN or an infinity is refused on reading, and an avatar holding one is never written (an edit or a
diverged fit cannot produce such a file).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import torch
from safetensors import SafetensorError, safe_open
from safetensors.torch import load, save

from gma.avatar.config import AvatarConfig
from gma.avatar.model import AvatarModel, DecodedAvatar
from gma.body import load_body
from gma.body.registry import BODY_MODELS
from gma.core.atomic import atomic_write_bytes
from gma.core.checks import require_finite
from gma.core.errors import InputError, NonFiniteError

__all__ = ["FORMAT_VERSION", "Avatar", "AvatarFileError"]

FORMAT_VERSION = 1
AVATAR_FORMAT = "gma"


class AvatarFileError(InputError):
    """A ``.gma`` file that cannot be read (the message names the file)."""


@dataclass(eq=False)
class Avatar:
    """A fitted avatar. ``model`` holds the layers; ``shape`` [S] the body identity; ``history`` the edit
    records (dicts, oldest first); ``info`` free-form metadata (fit summary)."""

    model: AvatarModel
    body_name: str
    shape: torch.Tensor
    rest_vertices: torch.Tensor
    history: list[dict] = field(default_factory=list)
    info: dict = field(default_factory=dict)
    face_seen: torch.Tensor | None = None  # [F] in [0, 1], or None for an avatar fitted without the record

    @property
    def config(self) -> AvatarConfig:
        return self.model.config

    @property
    def render_layer(self) -> str:
        """The layer a finished avatar shows: coarse surfels for the mesh-only ablation, else fine."""
        return "coarse" if self.config.representation == "mesh_only" else "fine"

    @staticmethod
    def create(config: AvatarConfig, body, shape: torch.Tensor | None = None, seed: int = 0) -> Avatar:
        """A fresh (unfitted) avatar on ``body`` with identity ``shape`` (default: the body's)."""
        params = body.canonical_params(None if shape is None else torch.as_tensor(shape, dtype=torch.float32))
        with torch.no_grad():
            rest = body.rest_vertices(params).float()
        model = AvatarModel(config, body.faces, rest, seed=seed)
        return Avatar(model, body.name, params["shape"].clone(), rest)

    @torch.no_grad()
    def decode(self, layer: str | None = None) -> DecodedAvatar:
        """Decode all faces (no autograd): the surfels to upload. Once per load or edit."""
        return self.model.decode(layer or self.render_layer).detach()

    # -- file IO ---------------------------------------------------------------------------------------
    def to_bytes(self, where: str = "avatar") -> bytes:
        """The ``.gma`` file's bytes; :class:`NonFiniteError` (naming ``where`` and the tensor) when a
        tensor holds a NaN or an infinity, or the expression in ``info`` does."""
        tensors = {f"model.{k}": v.detach().contiguous().cpu() for k, v in self.model.state_dict().items()}
        tensors["rest_vertices"] = self.rest_vertices.contiguous()
        tensors["shape"] = self.shape.float().contiguous()
        if self.face_seen is not None:
            tensors["face_seen"] = self.face_seen.float().contiguous()
        require_finite({_tensor_name(k): v for k, v in tensors.items()}, f"{where}: not written", NonFiniteError)
        if "expression" in self.info:
            require_finite({"the expression": self.info["expression"]}, f"{where}: not written", NonFiniteError)
        meta = {"format": AVATAR_FORMAT, "version": str(FORMAT_VERSION), "body": self.body_name,
                "config": json.dumps(self.config.to_dict()), "history": json.dumps(self.history),
                "info": json.dumps(self.info)}
        return canonical_safetensors(save(tensors, metadata=meta))

    def save(self, path: str | os.PathLike) -> Path:
        """Write the avatar to ``path`` atomically; returns the path."""
        path = Path(path)
        atomic_write_bytes(path, self.to_bytes(str(path)))
        return path

    @staticmethod
    def load(path: str | os.PathLike, body=None) -> Avatar:
        """Read a ``.gma`` file. ``body`` is the body model to bind to (default: ``load_body`` of the id the
        file names). Raises FileNotFoundError or :class:`AvatarFileError`, naming the file."""
        path = Path(path)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: avatar file not found")
        tensors, meta = read_gma(path)
        for key in ("config", "body"):
            if key not in meta:
                raise AvatarFileError(f"{path}: the avatar metadata has no {key!r} entry (damaged or not written "
                                      "by GMA)")
        try:
            config = AvatarConfig.from_dict(json.loads(meta["config"]))
            history, info = json.loads(meta.get("history", "[]")), json.loads(meta.get("info", "{}"))
        except (ValueError, TypeError, KeyError) as exc:
            raise AvatarFileError(f"{path}: bad avatar metadata ({exc})") from None
        if not isinstance(history, list) or not isinstance(info, dict):
            raise AvatarFileError(f"{path}: bad avatar metadata (history must be a list, info an object)")
        _check_info_expression(info, path)
        if meta["body"] not in BODY_MODELS:
            raise AvatarFileError(f"{path}: bound to body model {meta['body']!r}, which GMA does not know "
                                  f"({', '.join(BODY_MODELS)})")
        if body is None:
            body = load_body(meta["body"])
        if body.name != meta["body"]:
            raise AvatarFileError(f"{path}: avatar is bound to body {meta['body']!r}, got {body.name!r}")
        for key in ("rest_vertices", "shape"):
            if key not in tensors:
                raise AvatarFileError(f"{path}: missing tensor {key!r}")
        rest = tensors["rest_vertices"].float()
        if tuple(rest.shape) != (body.num_vertices, 3):
            raise AvatarFileError(f"{path}: rest_vertices is {list(rest.shape)}, body {body.name} has "
                                  f"{body.num_vertices} vertices")
        model = AvatarModel(config, body.faces, rest)
        state = {k[len("model."):]: v for k, v in tensors.items() if k.startswith("model.")}
        try:
            model.load_state_dict(state)
        except RuntimeError as exc:
            raise AvatarFileError(f"{path}: tensors do not match the avatar config ({exc})") from exc
        seen = _face_seen(path, tensors, model.num_faces)
        return Avatar(model, meta["body"], tensors["shape"].float(), rest, history, info, seen)


def _face_seen(path: Path, tensors: dict, num_faces: int) -> torch.Tensor | None:
    """The optional ``face_seen`` tensor, checked: [F] values in [0, 1]."""
    seen = tensors.get("face_seen")
    if seen is None:
        return None
    seen = seen.float()
    if tuple(seen.shape) != (num_faces,):
        raise AvatarFileError(f"{path}: face_seen is {list(seen.shape)}, the body has {num_faces} faces")
    if not bool(torch.isfinite(seen).all()) or float(seen.min()) < 0 or float(seen.max()) > 1:
        raise AvatarFileError(f"{path}: face_seen holds values outside [0, 1] (damaged file)")
    return seen


def _tensor_name(key: str) -> str:
    """The name a user knows a stored tensor by (``model.f_tex`` -> ``f_tex``)."""
    return key[len("model."):] if key.startswith("model.") else key


def _check_info_expression(info: dict, path: Path) -> None:
    """The default expression a body edit stores in ``info``: a list of finite numbers (JSON lets NaN in)."""
    if "expression" not in info:
        return
    expr = info["expression"]
    if not isinstance(expr, list) or not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in expr):
        raise AvatarFileError(f"{path}: bad avatar metadata (the expression must be a list of numbers)")
    require_finite({"the expression in its metadata": expr}, str(path), AvatarFileError)


def canonical_safetensors(data: bytes) -> bytes:
    """``data`` (a safetensors file) with its JSON header rewritten with sorted keys. safetensors writes
    the metadata from a hash map whose order changes from call to call; sorted, equal avatars give equal
    bytes (so undoing every edit gives back the very file)."""
    n = int.from_bytes(data[:8], "little")
    header = json.dumps(json.loads(data[8:8 + n]), sort_keys=True, separators=(",", ":")).encode()
    header += b" " * (-len(header) % 8)  # safetensors pads the header to 8 bytes for aligned tensor data
    return len(header).to_bytes(8, "little") + header + data[8 + n:]


def read_gma(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """(tensors, metadata) of a ``.gma`` file after format and version checks."""
    return read_tagged_file(path, {AVATAR_FORMAT: FORMAT_VERSION}, "a .gma avatar")


def read_tagged_file(path: Path, formats: dict[str, int], what: str) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """(tensors, metadata) of a GMA safetensors file whose metadata ``format`` is one of ``formats`` (format
    name -> newest version this GMA reads). Errors are :class:`AvatarFileError` naming the file and
    ``what`` was expected (e.g. "a .gma avatar")."""

    data = path.read_bytes()
    try:
        tensors = load(data)
        with safe_open(str(path), "pt") as f:
            meta = f.metadata() or {}
    except (SafetensorError, ValueError, OSError, RuntimeError) as exc:
        raise AvatarFileError(f"{path}: not {what} (not a readable safetensors file: {exc})") from exc
    kind = meta.get("format")
    if kind not in formats:
        raise AvatarFileError(f"{path}: safetensors file without the metadata of {what} (format={kind!r})")
    try:
        version = int(meta.get("version", ""))
    except ValueError:
        raise AvatarFileError(f"{path}: bad format version {meta.get('version')!r}") from None
    if version > formats[kind]:
        raise AvatarFileError(f"{path}: {kind} format version {version} is newer than this GMA supports "
                              f"({formats[kind]}); update GMA to open it")
    if version < 1:
        raise AvatarFileError(f"{path}: bad format version {version}")
    require_finite({_tensor_name(k): v for k, v in tensors.items()}, str(path), AvatarFileError)
    return tensors, meta
