"""Small "fitted" avatars for the editing tests: a fresh avatar's decoders are random, so its features
span no useful colours; a few hundred Adam steps on a made-up garment pattern (shirt, trousers, skin)
give decoders and features shaped like a fit's, in seconds."""

from __future__ import annotations

import functools

import torch

from gma.avatar import Avatar, AvatarConfig

SMALL = dict(feature_dim=16, fine_per_face=2, hidden=64)
GARMENTS = {"torso": (0.2, 0.3, 0.7), "arms": (0.8, 0.6, 0.5), "hands": (0.8, 0.6, 0.5), "head": (0.75, 0.55, 0.45),
            "legs": (0.25, 0.22, 0.2), "feet": (0.1, 0.1, 0.1)}


def garment_colors(body, pe: torch.Tensor, nk: int) -> torch.Tensor:
    """[F, nk, 3] target colours: one colour per region with a gentle stripe from the positional encoding."""
    target = torch.full((body.num_faces, 3), 0.5)
    for region, rgb in GARMENTS.items():
        target[body.region_mask(region)] = torch.tensor(rgb)
    stripe = 0.08 * torch.sin(6.0 * pe[:, 2:3])  # PE column 2: the normalised height
    # A fabric-like per-face speckle of every hue: the decoders of a real fit have seen a wide palette
    # (the inverse of a decoder trained on six flat colours reaches little else).
    speckle = torch.rand(body.num_faces, 3, generator=torch.Generator().manual_seed(0)) - 0.5
    return (target + stripe + 0.35 * speckle).clamp(0.02, 0.98)[:, None, :].expand(-1, nk, 3)


def pseudo_fit(avatar: Avatar, body, steps: int = 150, lr: float = 1e-2) -> Avatar:
    """Fit f_tex, T_color and T_scale of ``avatar`` to the garment colours (scales kept at their start)."""
    m = avatar.model
    nk = m.config.fine_per_face
    target = garment_colors(body, m.pe, nk).reshape(body.num_faces, -1)
    params = [m.f_tex, *m.T_color.parameters(), *m.T_scale.parameters()]
    opt = torch.optim.Adam(params, lr=lr)
    with torch.no_grad():
        s0 = m.T_scale(torch.cat([m.f_tex, m.pe], -1))
    for _ in range(steps):
        inp = torch.cat([m.f_tex, m.pe], -1)
        loss = (torch.sigmoid(m.T_color(inp)) - target).square().mean() + 0.1 * (m.T_scale(inp) - s0).square().mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    m.zero_grad(set_to_none=True)
    return avatar


@functools.lru_cache(maxsize=4)
def _fitted_state(body_name: str, shape_key: tuple | None, seed: int, config_items: tuple) -> tuple:
    from gma.body import load_body

    body = load_body(body_name)
    shape = None if shape_key is None else torch.tensor(shape_key)
    av = Avatar.create(AvatarConfig(**dict(config_items)), body, shape, seed=seed)
    pseudo_fit(av, body)
    return av.to_bytes(), av


def fitted_avatar(body, shape=None, seed: int = 0, **config) -> Avatar:
    """A fresh copy of a pseudo-fitted small avatar (cached per arguments within the test session)."""
    from safetensors.torch import load

    cfg = {**SMALL, **config}
    key = None if shape is None else tuple(float(v) for v in shape)
    _, av = _fitted_state(body.name, key, seed, tuple(sorted(cfg.items())))
    out = Avatar.create(av.config, body, av.shape, seed=seed)
    state = {k[len("model."):]: v for k, v in load(av.to_bytes()).items() if k.startswith("model.")}
    out.model.load_state_dict(state)
    return out


def varied_avatar(body) -> Avatar:
    """A small avatar (8 features, one surfel a face) with varied colours, scales and offsets: its
    decoders' weights shifted by seeded noise, so exports and renders have structure to compare."""
    av = Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1), body, seed=1)
    g = torch.Generator().manual_seed(0)
    with torch.no_grad():
        for p in av.model.parameters():
            p.add_(0.3 * torch.randn(p.shape, generator=g))
    return av
