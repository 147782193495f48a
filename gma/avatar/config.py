"""Configuration of the avatar representation (what a ``.gma`` file records, beside its tensors)."""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields

__all__ = ["ABLATIONS", "AvatarConfig", "doc"]

# The paper's ablation table: "full" is the method; the others switch one design choice off.
ABLATIONS = ("full", "mesh_only", "direct")


def doc(default, text: str):
    """A dataclass field with a default and a one-line doc (shown by the CLI built from the dataclass)."""
    if isinstance(default, (list, dict, tuple)):
        return field(default_factory=lambda: type(default)(default), metadata={"doc": text})
    return field(default=default, metadata={"doc": text})


@dataclass
class AvatarConfig:
    """Sizes and output ranges of the three layers (features → decoders → surfels)."""

    body: str = doc("anny", "body model id the avatar is bound to")
    feature_dim: int = doc(32, "k: length of the per-face features f_geo and f_tex")
    hidden: int = doc(128, "hidden width of every decoder MLP (the paper's 128)")
    pe_freqs: int = doc(4, "NeRF-style sin/cos frequencies of the canonical face centre")
    fine_per_face: int = doc(4, "N_k: fine surfels per face")
    offset_max: float = doc(0.08, "largest |normal offset| of the mesh layer, metres (tanh bound)")
    fine_offset_max: float = doc(0.01, "largest |d| of a fine surfel off the morphed face, metres")
    coarse_scale: float = doc(0.6, "in-face scale of a coarse surfel (times sqrt(face area))")
    fine_scale: float = doc(0.65, "initial in-face scale of a fine surfel, before / sqrt(N_k)")
    opacity: float = doc(0.99, "fixed surfel opacity (the paper fixes 1; 0.99 keeps one surfel from "
                               "ending compositing outright, so occluded layers still get gradients)")
    representation: str = doc("full", "full | mesh_only (coarse surfels only) | direct (free per-surfel "
                                      "parameters on the body's own faces: no features, decoders or mesh "
                                      "layer; fitted in one stage)")

    def __post_init__(self):
        if self.representation not in ABLATIONS:
            raise ValueError(f"representation must be one of {ABLATIONS}, got {self.representation!r}")
        if self.feature_dim < 1 or self.hidden < 1 or self.fine_per_face < 1 or self.pe_freqs < 0:
            raise ValueError(f"feature_dim, hidden, fine_per_face must be >= 1 and pe_freqs >= 0: {self}")

    def to_dict(self) -> dict:
        return asdict(self)

    @staticmethod
    def from_dict(d: dict) -> AvatarConfig:
        known = {f.name for f in fields(AvatarConfig)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(f"unknown avatar config keys {sorted(unknown)}")
        return AvatarConfig(**d)
