"""The Gaussian Morphing Avatar's three layers in torch: per-face features, the four decoders, and
decoding into the mesh layer (per-vertex normal offsets) and surfel bindings.

    f_geo, f_tex [F, k]  +  PE(canonical face centre) [F, P]
      F_coarse(f_geo, PE) -> [F, 3] offset scale per face corner -> averaged onto vertices -> O [V]
      F_fine  (f_geo, PE) -> [F, N_k, 4] barycentric logits (3) and normal offset d
      T_color (f_tex, PE) -> [F, N_k, 3] RGB;   T_scale(f_tex, PE) -> [F, N_k, 2] in-face scales

The morphed mesh is ``rest + O[:, None] · N_v`` (N_v the canonical vertex normals; the paper's
X_i = X_f + 1/3 Σ_k O_k N_{v,k} is then the morphed face centre). Fine surfels sit at (u, v, d) on the
morphed faces; coarse surfels (stage 1) at the morphed face centres with the mean of the fine colours.

Representation ``direct`` (ablation: the paper's Gaussians embedded directly in the body model's local
coordinates) has no features, no decoders and no mesh layer: free per-surfel parameters in the body's
own faces, through the same output heads, with a normal offset d that reaches as far as the mesh layer
and a fine surfel together (``offset_max + fine_offset_max``), so clothing is reachable.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

from gma.avatar.config import AvatarConfig
from gma.body.geometry import vertex_normals
from gma.body.placement import SurfelBinding, uniform_surfels

__all__ = ["DECODER_NAMES", "AvatarModel", "DecodedAvatar", "Mlp", "positional_encoding"]

DECODER_NAMES = ("F_coarse", "F_fine", "T_color", "T_scale")


def positional_encoding(x: torch.Tensor, freqs: int) -> torch.Tensor:
    """NeRF-style encoding of points [..., 3] (already scaled to about [-1, 1]) -> [..., 3 + 6·freqs]."""
    out = [x]
    for i in range(freqs):
        out += [torch.sin((2.0**i) * math.pi * x), torch.cos((2.0**i) * math.pi * x)]
    return torch.cat(out, -1)


class Mlp(nn.Sequential):
    """Linear -> activation -> Linear (the paper's F* use GELU, T* ReLU). The last layer starts small so
    that a fresh avatar decodes to its head biases (a uniform layer of surfels on the body)."""

    def __init__(self, d_in: int, hidden: int, d_out: int, act: str, out_gain: float = 0.1):
        super().__init__(nn.Linear(d_in, hidden), nn.GELU() if act == "gelu" else nn.ReLU(), nn.Linear(hidden, d_out))
        with torch.no_grad():
            self[2].weight.mul_(out_gain)
            self[2].bias.zero_()


@dataclass
class DecodedAvatar:
    """Decoded surfels ready for posing. N = number of surfels.

    vertex_offsets: [V, 3] morph added to the body's rest vertices (m); binding: SurfelBinding of N;
    colors [N, 3] in [0, 1]; opacities [N]. Tensors keep their autograd graph while training.
    """

    vertex_offsets: torch.Tensor
    binding: SurfelBinding
    colors: torch.Tensor
    opacities: torch.Tensor

    def detach(self) -> DecodedAvatar:
        b = self.binding
        return DecodedAvatar(self.vertex_offsets.detach(),
                             SurfelBinding(b.face_id, b.uv.detach(), b.offset.detach(), b.scale.detach(),
                                           b.quat.detach()),
                             self.colors.detach(), self.opacities.detach())


def _inv_softplus(y: float) -> float:
    return math.log(math.expm1(y))


class AvatarModel(nn.Module):
    """Features + decoders of one avatar, bound to a body topology.

    Args:
        config: sizes and ranges. faces: [F, 3] body faces. rest_vertices: [V, 3] the body's canonical
        (rest-pose) vertices at the avatar's identity shape; their face centres feed the positional
        encoding and their normals carry the mesh-layer offsets, both fixed for the avatar's life (so a
        later shape edit does not change what the decoders see).
    """

    def __init__(self, config: AvatarConfig, faces: torch.Tensor, rest_vertices: torch.Tensor, seed: int = 0):
        super().__init__()
        self.config = c = config
        faces = faces.long()
        nf, nv, k, nk = faces.shape[0], rest_vertices.shape[0], c.feature_dim, c.fine_per_face
        self.register_buffer("faces", faces, persistent=False)
        rest = rest_vertices.detach().float()
        centers = rest[faces].mean(1)
        lo, hi = rest.min(0).values, rest.max(0).values
        scaled = (centers - 0.5 * (lo + hi)) / (0.5 * (hi - lo).max())
        self.register_buffer("pe", positional_encoding(scaled, c.pe_freqs), persistent=False)  # [F, P]
        normals = nn.functional.normalize(vertex_normals(rest, faces), dim=-1)
        self.register_buffer("vertex_normals", normals, persistent=False)  # [V, 3]
        # Each vertex averages the corner predictions of its incident faces.
        count = torch.zeros(nv).index_add_(0, faces.reshape(-1), torch.ones(faces.numel()))
        self.register_buffer("vertex_count", count.clamp_min(1.0), persistent=False)

        # Head biases: stratified barycentric slots, a scale that tiles the face, mid-grey colour.
        slots = uniform_surfels(1, nk, seed=0).uv  # [N_k, 2]; fixed seed: part of the format, not the avatar
        bary = torch.cat([slots, 1 - slots.sum(1, keepdim=True)], 1).clamp_min(0.02)
        fine_bias = torch.cat([bary.log(), torch.zeros(nk, 1)], 1)  # [N_k, 4]
        scale_bias = torch.full((nk, 2), _inv_softplus(c.fine_scale / math.sqrt(nk)))
        self.register_buffer("fine_bias", fine_bias, persistent=False)
        self.register_buffer("scale_bias", scale_bias, persistent=False)

        g = torch.Generator().manual_seed(seed)
        p = self.pe.shape[1]
        if c.representation == "direct":
            self.fine_raw = nn.Parameter(torch.zeros(nf, nk, 4))
            self.color_raw = nn.Parameter(torch.zeros(nf, nk, 3))
            self.scale_raw = nn.Parameter(torch.zeros(nf, nk, 2))
        else:
            self.f_geo = nn.Parameter(0.1 * torch.randn(nf, k, generator=g))
            self.f_tex = nn.Parameter(0.1 * torch.randn(nf, k, generator=g))
            torch.manual_seed(seed)  # decoder init follows the avatar seed, not the caller's RNG state
            self.F_coarse = Mlp(k + p, c.hidden, 3, "gelu")
            self.F_fine = Mlp(k + p, c.hidden, 4 * nk, "gelu")
            self.T_color = Mlp(k + p, c.hidden, 3 * nk, "relu", out_gain=1.0)  # colours must move fast
            self.T_scale = Mlp(k + p, c.hidden, 2 * nk, "relu")

    @property
    def num_faces(self) -> int:
        return int(self.faces.shape[0])

    @property
    def direct(self) -> bool:
        return self.config.representation == "direct"

    @property
    def d_max(self) -> float:
        """Largest |d| of a fine surfel off its face (m): off the morphed face, or off the body's own face
        for ``direct``, which has no mesh layer to carry it out to the clothing."""
        c = self.config
        return c.offset_max + c.fine_offset_max if self.direct else c.fine_offset_max

    # -- groups of parameters (the trainer freezes by group) -------------------------------------------
    def param_groups(self) -> dict[str, list[nn.Parameter]]:
        """Named parameter groups: ``geo_coarse`` (f_geo, F_coarse; none for ``direct``), ``geo_fine``
        (F_fine / free surfel positions), ``tex`` (f_tex, T_color, T_scale / free colours and scales)."""
        if self.direct:
            return {"geo_coarse": [], "geo_fine": [self.fine_raw],
                    "tex": [self.color_raw, self.scale_raw]}
        return {"geo_coarse": [self.f_geo, *self.F_coarse.parameters()], "geo_fine": list(self.F_fine.parameters()),
                "tex": [self.f_tex, *self.T_color.parameters(), *self.T_scale.parameters()]}

    def share_decoders_with(self, other: AvatarModel) -> None:
        """Use ``other``'s decoder modules — the same parameters, not copies — so that avatars fitted
        together train one set of decoders (the paper's shared decoders)."""
        if self.direct or other.direct:
            raise ValueError("the 'direct' representation has no decoders to share")
        if self.config != other.config:
            raise ValueError(f"decoders are shared only between avatars of one config: {self.config} vs "
                             f"{other.config}")
        for name in DECODER_NAMES:
            setattr(self, name, getattr(other, name))

    def decoder_state(self) -> dict[str, torch.Tensor]:
        """The decoder weights only (shared across avatars by ``--decoders``)."""
        return {k: v for k, v in self.state_dict().items() if not k.startswith(("f_geo", "f_tex"))}

    # -- decoding --------------------------------------------------------------------------------------
    def _inputs(self, feat: torch.Tensor, face_ids: torch.Tensor | None) -> torch.Tensor:
        pe = self.pe if face_ids is None else self.pe[face_ids]
        f = feat if face_ids is None else feat[face_ids]
        return torch.cat([f, pe], -1)

    def vertex_offset_scale(self) -> torch.Tensor:
        """[V] signed normal offsets of the mesh layer (m); zero for ``direct``, which has none."""
        if self.direct:
            return torch.zeros_like(self.vertex_count)
        corner = self.F_coarse(self._inputs(self.f_geo, None))  # [F, 3]
        raw = torch.zeros_like(self.vertex_count).index_add(0, self.faces.reshape(-1), corner.reshape(-1))
        return self.config.offset_max * torch.tanh(raw / self.vertex_count)

    def vertex_offsets(self) -> torch.Tensor:
        """[V, 3] morph displacements (offset scale times canonical vertex normal)."""
        return self.vertex_offset_scale()[:, None] * self.vertex_normals

    def fine_outputs(self, face_ids: torch.Tensor | None = None) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(uvd [F', N_k, 3], colours [F', N_k, 3], in-face scales [F', N_k, 2]) for ``face_ids`` (all faces
        when None). u, v are barycentric weights of V1, V2 (softmax, so inside the triangle)."""
        nk = self.config.fine_per_face
        if self.direct:
            sel = (lambda t: t) if face_ids is None else (lambda t: t[face_ids])
            fine_raw, color_raw, scale_raw = sel(self.fine_raw), sel(self.color_raw), sel(self.scale_raw)
        else:
            g, t = self._inputs(self.f_geo, face_ids), self._inputs(self.f_tex, face_ids)
            fine_raw = self.F_fine(g).reshape(-1, nk, 4)
            color_raw = self.T_color(t).reshape(-1, nk, 3)
            scale_raw = self.T_scale(t).reshape(-1, nk, 2)
        fine_raw = fine_raw + self.fine_bias
        bary = torch.softmax(fine_raw[..., :3], -1)
        d = self.d_max * torch.tanh(fine_raw[..., 3:])
        uvd = torch.cat([bary[..., :2], d], -1)
        colors = torch.sigmoid(color_raw)
        scales = nn.functional.softplus(scale_raw + self.scale_bias)
        return uvd, colors, scales

    def decode(self, layer: str = "fine") -> DecodedAvatar:
        """Decode every face. ``layer`` "fine": N_k surfels per face (the final avatar); "coarse": one
        surfel per face at the morphed face centre, coloured by the mean fine colour (stage 1)."""
        nf, nk = self.num_faces, self.config.fine_per_face
        offsets = self.vertex_offsets()
        uvd, colors, scales = self.fine_outputs()
        quat = torch.zeros(1, 4, device=uvd.device)
        quat[0, 0] = 1
        if layer == "coarse":
            fid = torch.arange(nf, device=uvd.device)
            binding = SurfelBinding(fid, torch.full((nf, 2), 1 / 3), torch.zeros(nf),
                                    torch.full((nf, 2), self.config.coarse_scale), quat.expand(nf, 4))
            colors = colors.mean(1)
        elif layer == "fine":
            n = nf * nk
            fid = torch.arange(nf, device=uvd.device).repeat_interleave(nk)
            binding = SurfelBinding(fid, uvd[..., :2].reshape(n, 2), uvd[..., 2].reshape(n),
                                    scales.reshape(n, 2), quat.expand(n, 4))
            colors = colors.reshape(n, 3)
        else:
            raise ValueError(f"layer must be 'coarse' or 'fine', got {layer!r}")
        opac = torch.full((len(binding),), self.config.opacity)
        return DecodedAvatar(offsets, binding, colors, opac)

    @torch.no_grad()
    def redecode_faces(self, decoded: DecodedAvatar, face_ids: torch.Tensor, mesh: bool = True) -> torch.Tensor:
        """Update a fine ``decoded`` in place after an edit of the features of ``face_ids`` [M]; returns the
        surfel indices [M·N_k] that changed (rows of the GPU buffers to rewrite). The mesh layer is
        recomputed whole: it is one small MLP pass, and a vertex mixes its neighbours' faces; ``mesh=False``
        skips it (an edit of f_tex only cannot move the mesh)."""
        nk = self.config.fine_per_face
        face_ids = torch.as_tensor(face_ids, dtype=torch.long).unique()
        uvd, colors, scales = self.fine_outputs(face_ids)
        rows = (face_ids[:, None] * nk + torch.arange(nk)).reshape(-1)
        decoded.binding.uv[rows] = uvd[..., :2].reshape(-1, 2)
        decoded.binding.offset[rows] = uvd[..., 2].reshape(-1)
        decoded.binding.scale[rows] = scales.reshape(-1, 2)
        decoded.colors[rows] = colors.reshape(-1, 3)
        if mesh:
            decoded.vertex_offsets.copy_(self.vertex_offsets())
        return rows
