"""Paint: new ``f_tex`` for the touched faces so that the frozen ``T_color`` decodes target colours.

Targets are per surfel: a colour and a weight in [0, 1] (brush falloff, stamp alpha). A surfel's goal
colour is ``w·target + (1 − w)·current``; surfels of weight 0 in a touched face keep their current raw
colour as the goal (a partly painted face keeps its unpainted surfels), and ``T_scale``'s raw outputs
are kept as a second head, since ``f_tex`` drives both. Solved by :func:`gma.edit.invert.solve_features`
(see there for why Gauss–Newton), anchored at the old feature.
"""

from __future__ import annotations

import re

import numpy as np
import torch

from gma.edit.errors import EditError
from gma.edit.invert import Head, InvertConfig, solve_features

__all__ = ["NAMED_COLORS", "paint_features", "parse_color"]

NAMED_COLORS = {"red": (1.0, 0.0, 0.0), "green": (0.0, 0.5, 0.0), "blue": (0.0, 0.0, 1.0), "black": (0.0, 0.0, 0.0),
                "white": (1.0, 1.0, 1.0), "grey": (0.5, 0.5, 0.5), "gray": (0.5, 0.5, 0.5),
                "yellow": (1.0, 1.0, 0.0), "cyan": (0.0, 1.0, 1.0), "magenta": (1.0, 0.0, 1.0)}


def parse_color(text) -> tuple[float, float, float]:
    """An sRGB colour in [0, 1] from ``#rrggbb``, ``#rgb``, ``r,g,b`` (floats in [0, 1]), a colour name,
    or a sequence of three numbers. Raises EditError naming the text."""
    if not isinstance(text, str):
        try:
            rgb = tuple(float(v) for v in text)
        except TypeError:
            raise EditError(f"colour must be a string or three numbers, got {text!r}") from None
    else:
        s = text.strip().lower()
        if s in NAMED_COLORS:
            return NAMED_COLORS[s]
        if m := re.fullmatch(r"#?([0-9a-f]{6}|[0-9a-f]{3})", s):
            h = m.group(1)
            h = "".join(c * 2 for c in h) if len(h) == 3 else h
            return tuple(int(h[i:i + 2], 16) / 255.0 for i in (0, 2, 4))
        try:
            rgb = tuple(float(v) for v in s.split(","))
        except ValueError:
            raise EditError(f"cannot parse colour {text!r}: use #rrggbb, r,g,b in [0, 1], or a name "
                            f"({', '.join(sorted(NAMED_COLORS))})") from None
    if len(rgb) != 3 or not all(np.isfinite(rgb)) or min(rgb) < 0 or max(rgb) > 1:
        raise EditError(f"colour {text!r} must be three values in [0, 1]")
    return rgb


@torch.no_grad()
def paint_features(model, face_ids: torch.Tensor, colors, weights=None, config: InvertConfig | None = None
                   ) -> tuple[torch.Tensor, dict]:
    """New f_tex [M, k] for faces ``face_ids`` [M] of ``model`` (an AvatarModel).

    colors: [3], [M, 3] or [M, N_k, 3] target RGB in [0, 1]. weights: None (1), [M] per face or [M, N_k]
    per surfel, in [0, 1]. Returns (features, info from the solver)."""
    cfg = config or InvertConfig()
    if model.direct:
        raise EditError("a 'direct' avatar has no features to paint (it has no decoders to invert)")
    nk = model.config.fine_per_face
    ids = torch.as_tensor(face_ids, dtype=torch.long)
    m = len(ids)
    col = torch.as_tensor(np.asarray(colors, np.float32))
    shape = {1: (1, 1, 3), 2: (-1, 1, 3), 3: (-1, nk, 3)}[col.dim()]
    col = col.reshape(shape).expand(m, nk, 3)
    w = torch.ones(m, nk) if weights is None else torch.as_tensor(np.asarray(weights, np.float32))
    w = (w.reshape(m, 1) if w.dim() == 1 else w).expand(m, nk).clamp(0, 1).unsqueeze(-1)
    feat, pe = model.f_tex[ids], model.pe[ids]
    inp = torch.cat([feat, pe], -1)
    raw_c = model.T_color(inp).reshape(m, nk, 3)
    raw_s = model.T_scale(inp)
    goal = w * col + (1 - w) * torch.sigmoid(raw_c)
    goal = torch.logit(goal.clamp(cfg.margin, 1 - cfg.margin))
    goal = torch.where(w > 0, goal, raw_c)  # untouched surfels: their exact current logits
    heads = [Head(model.T_color, goal.reshape(m, -1)), Head(model.T_scale, raw_s, cfg.scale_weight)]
    return solve_features(heads, feat, pe, feat, cfg)
