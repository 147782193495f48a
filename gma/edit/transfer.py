"""Cross-identity feature transfer: the selected faces of a target avatar take ``f_geo``, ``f_tex`` or
both from a donor avatar (the paper's trousers shape, denim texture, hood).

Decoders must be shared (same weights and config); ``gma fit --decoders`` gives two fits the same ones.

The decoders also read the positional encoding of the canonical face centre, and each avatar computes it
from its own rest vertices, normalised by its own bounding box. On two body shapes the same face has a
different PE, so the same feature decodes to something else (a taller person's chest face sits at
another normalised height). Same shape (identical PE on the selected faces): the rows are copied and
decode bit-identically. Different shape: the target's features are *fitted* so that its decoders, on
its own PE, output what the donor's decode on the donor's PE (raw outputs of every head the feature
drives), starting from and anchored at the donor's features (:func:`gma.edit.invert.solve_features`).
"""

from __future__ import annotations

import torch

from gma.avatar.config import AvatarConfig
from gma.edit.errors import EditError
from gma.edit.invert import Head, InvertConfig, solve_features

__all__ = ["WHAT", "check_shared_decoders", "transfer_features"]

WHAT = {"tex": ("f_tex",), "geo": ("f_geo",), "both": ("f_geo", "f_tex")}


def check_shared_decoders(target, donor, target_name: str = "target", donor_name: str = "donor") -> None:
    """Raise EditError naming both files and what differs unless ``target`` and ``donor`` (AvatarModels)
    have the same config and the same decoder weights."""
    if target.direct or donor.direct:
        raise EditError(f"{target_name} / {donor_name}: a 'direct' avatar has no features to transfer")
    differ = [f"{k} {getattr(donor.config, k)!r} vs {getattr(target.config, k)!r}"
              for k in AvatarConfig.__dataclass_fields__ if getattr(donor.config, k) != getattr(target.config, k)]
    if target.num_faces != donor.num_faces:
        differ.append(f"faces {donor.num_faces} vs {target.num_faces}")
    if not differ:
        mine, theirs = target.decoder_state(), donor.decoder_state()
        differ = [f"decoder weights {name}" for name in mine
                  if name not in theirs or not torch.equal(mine[name], theirs[name])]
    if differ:
        shown = "; ".join(differ[:4]) + (f"; and {len(differ) - 4} more" if len(differ) > 4 else "")
        raise EditError(f"cannot transfer from {donor_name} to {target_name}: they do not share decoders "
                        f"({shown}); fit both against one decoders file with `gma fit --decoders`")


@torch.no_grad()
def transfer_features(target, donor, face_ids: torch.Tensor, what: str = "tex", mode: str = "auto",
                      config: InvertConfig | None = None) -> tuple[dict[str, torch.Tensor], dict]:
    """New feature rows for ``face_ids`` [M] of ``target`` from ``donor`` (AvatarModels with shared
    decoders). what: tex | geo | both. mode: "copy" (rows as they are), "fit" (match the donor's decoded
    outputs on the target's own PE), "auto" (copy where the PE of the selected faces is identical, else
    fit). Returns ({"f_geo"/"f_tex": [M, k]}, info with "mode")."""
    if what not in WHAT:
        raise EditError(f"transfer what must be one of {', '.join(WHAT)}, got {what!r}")
    if mode not in ("auto", "copy", "fit"):
        raise EditError(f"transfer mode must be auto, copy or fit, got {mode!r}")
    ids = torch.as_tensor(face_ids, dtype=torch.long)
    pe_t, pe_d = target.pe[ids], donor.pe[ids]
    if mode == "auto":
        mode = "copy" if torch.equal(pe_t, pe_d) else "fit"
    out: dict[str, torch.Tensor] = {}
    info = {"mode": mode}
    for name in WHAT[what]:
        donor_feat = getattr(donor, name)[ids].clone()
        if mode == "copy":
            out[name] = donor_feat
            continue
        inp = torch.cat([donor_feat, pe_d], -1)
        if name == "f_tex":
            heads = [Head(target.T_color, donor.T_color(inp)), Head(target.T_scale, donor.T_scale(inp))]
        else:
            # The mesh layer's corner scales pass through tanh·offset_max (a few cm): weight them up so a
            # millimetre of offset costs as much as a small change of a fine surfel's logits.
            heads = [Head(target.F_fine, donor.F_fine(inp)), Head(target.F_coarse, donor.F_coarse(inp), 10.0)]
        out[name], res = solve_features(heads, donor_feat, pe_t, donor_feat, config)
        info[f"{name}_iterations"] = res["iterations"]
    return out, info
