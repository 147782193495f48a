"""Edit records: what ``Avatar.history`` holds, and how a record undoes itself.

A record is a JSON dict (the ``.gma`` file keeps the list in its metadata)::

    {"op": "paint", "params": {...}, "faces": <M>, "face_ids": <b64 int32 [M]>,
     "old": {"f_tex": {"shape": [M, k], "data": <b64 float32>}, ...}, "old_info": {...}}

``old`` holds only the touched faces' rows of the fields the edit changed (or the whole ``shape``
tensor for a body edit), as raw little-endian float32 bytes in base64, so restoring is bit-exact;
``old_info`` the previous values of the ``info`` keys a body edit wrote (null: the key was absent).
"""

from __future__ import annotations

import base64

import numpy as np
import torch

from gma.edit.errors import EditError

__all__ = ["FEATURE_FIELDS", "decode_tensor", "encode_tensor", "make_record", "record_face_ids", "record_old",
           "restore_record"]

FEATURE_FIELDS = ("f_geo", "f_tex")


def encode_tensor(t: torch.Tensor, dtype=np.float32) -> dict:
    a = np.ascontiguousarray(t.detach().cpu().numpy().astype(dtype)).astype(np.dtype(dtype).newbyteorder("<"))
    return {"shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode("ascii")}


def decode_tensor(d: dict, dtype=np.float32) -> torch.Tensor:
    a = np.frombuffer(base64.b64decode(d["data"]), np.dtype(dtype).newbyteorder("<")).astype(dtype)
    return torch.from_numpy(a.reshape(d["shape"]).copy())


def make_record(op: str, params: dict, face_ids: torch.Tensor | None, old: dict[str, torch.Tensor],
                old_info: dict | None = None) -> dict:
    """A history record of an edit about to be applied: ``old`` the values it overwrites."""
    rec = {"op": op, "params": params}
    if face_ids is not None:
        rec["faces"] = int(len(face_ids))
        rec["face_ids"] = encode_tensor(face_ids, np.int32)
    rec["old"] = {k: encode_tensor(v) for k, v in old.items()}
    if old_info is not None:
        rec["old_info"] = old_info
    return rec


def record_face_ids(rec: dict) -> torch.Tensor | None:
    return decode_tensor(rec["face_ids"], np.int32).long() if "face_ids" in rec else None


def record_old(rec: dict) -> dict[str, torch.Tensor]:
    return {k: decode_tensor(v) for k, v in rec.get("old", {}).items()}


@torch.no_grad()
def restore_record(avatar, rec: dict) -> dict[str, torch.Tensor]:
    """Put back what ``rec`` overwrote on ``avatar``; returns the values it replaced (what redo needs),
    in the same layout as ``record_old``."""
    try:
        faces, old = record_face_ids(rec), record_old(rec)
    except (KeyError, ValueError, TypeError) as exc:
        raise EditError(f"history record {rec.get('op', '?')!r} is malformed ({exc})") from None
    return apply_values(avatar, faces, old, rec.get("old_info"))


@torch.no_grad()
def apply_values(avatar, faces: torch.Tensor | None, values: dict[str, torch.Tensor], info: dict | None = None
                 ) -> dict[str, torch.Tensor]:
    """Write feature rows / shape ``values`` (and ``info`` keys; None deletes one) into ``avatar``;
    returns the previous values in the same layout."""
    model = avatar.model
    before: dict[str, torch.Tensor] = {}
    for name, value in values.items():
        if name in FEATURE_FIELDS:
            param = getattr(model, name)
            before[name] = param[faces].clone()
            param[faces] = value.to(param.dtype)
        elif name == "shape":
            before[name] = avatar.shape.clone()
            avatar.shape = value.clone().to(avatar.shape.dtype)
        else:
            raise EditError(f"history record changes unknown field {name!r}")
    for key, value in (info or {}).items():
        if value is None:
            avatar.info.pop(key, None)
        else:
            avatar.info[key] = value
    return before
