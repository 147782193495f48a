"""The synthetic person's UV texture, painted procedurally from 3D rest-pose positions.

Each garment gets distinct high-frequency content so that a fitted avatar's sharpness is measurable:
a striped shirt with pinstripes, stitched side seams, cuff and hem bands, a printed logo and text on the
chest and a number on the back; checked trousers with a side stripe; sneakers with a sole and laces;
hair with fine strands; skin with eyes, brows and lips. Colours and sizes are drawn from the seed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from PIL import Image, ImageDraw, ImageFont

from gma.synth.garments import COLLAR, HAIR, HOOD, SHIRT, SHOES, SKIN, TROUSERS, Garments
from gma.synth.uv_bake import dilate, rasterize_uv

__all__ = ["Look", "bake_texture"]

_PALETTE = np.array(
    [
        (0.80, 0.15, 0.15),
        (0.10, 0.30, 0.70),
        (0.95, 0.75, 0.10),
        (0.10, 0.55, 0.30),
        (0.95, 0.95, 0.92),
        (0.12, 0.12, 0.14),
        (0.55, 0.20, 0.60),
        (0.95, 0.45, 0.10),
        (0.20, 0.65, 0.80),
        (0.45, 0.30, 0.18),
    ]
)
_SKIN = np.array(
    [(0.96, 0.80, 0.69), (0.87, 0.67, 0.52), (0.72, 0.52, 0.38), (0.50, 0.34, 0.24), (0.36, 0.24, 0.17)]
)
_HAIR = np.array([(0.08, 0.06, 0.05), (0.30, 0.18, 0.08), (0.62, 0.45, 0.22), (0.55, 0.22, 0.10)])
_WORDS = ("GMA", "AVATAR", "SURFEL", "BRUSH", "WGSL")


@dataclass
class Look:
    """Seeded appearance choices (colours RGB in [0, 1], lengths in metres)."""

    shirt: np.ndarray
    stripe: np.ndarray
    trousers: np.ndarray
    check: np.ndarray
    shoes: np.ndarray
    skin: np.ndarray
    hair: np.ndarray
    stripe_period: float
    check_period: float
    word: str
    number: int

    @classmethod
    def from_seed(cls, rng: np.random.Generator) -> Look:
        c = rng.permutation(len(_PALETTE))
        return cls(
            shirt=_PALETTE[c[0]],
            stripe=_PALETTE[c[1]],
            trousers=_PALETTE[c[2]] * 0.7,
            check=_PALETTE[c[3]],
            shoes=np.array([0.93, 0.93, 0.93]),
            skin=_SKIN[rng.integers(len(_SKIN))],
            hair=_HAIR[rng.integers(len(_HAIR))],
            stripe_period=float(rng.uniform(0.025, 0.04)),
            check_period=float(rng.uniform(0.04, 0.06)),
            word=_WORDS[rng.integers(len(_WORDS))],
            number=int(rng.integers(1, 100)),
        )


def _font(size: int) -> ImageFont.ImageFont:
    # A TrueType font when the system has one; Pillow's built-in font otherwise (always available).
    for name in ("DejaVuSans-Bold.ttf", "LiberationSans-Bold.ttf", "Arial Bold.ttf"):
        try:
            return ImageFont.truetype(name, size)
        except OSError:
            continue
    return ImageFont.load_default(size=size)


def _decal(text: str, logo: bool, w: int = 512, h: int = 256) -> np.ndarray:
    """A print: ``text`` under an optional ring-and-star logo; float alpha [h, w] in [0, 1]."""
    img = Image.new("L", (w, h), 0)
    d = ImageDraw.Draw(img)
    if logo:
        cx, cy, r = w // 2, h // 3, h // 4
        d.ellipse((cx - r, cy - r, cx + r, cy + r), outline=255, width=max(2, r // 6))
        ang = np.pi / 2 + np.arange(10) * np.pi / 5
        rad = np.where(np.arange(10) % 2 == 0, 0.75 * r, 0.3 * r)
        d.polygon(
            [(cx + rr * np.cos(a), cy - rr * np.sin(a)) for a, rr in zip(ang, rad, strict=True)], fill=255
        )
    font = _font(h // 3 if logo else int(h * 0.8))
    box = d.textbbox((0, 0), text, font=font)
    tw, th = box[2] - box[0], box[3] - box[1]
    ty = (h * 2) // 3 - th // 2 if logo else (h - th) // 2
    d.text(((w - tw) // 2 - box[0], ty - box[1]), text, fill=255, font=font)
    return np.asarray(img, np.float32) / 255.0


def _sample(decal: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Nearest lookup in a decal at (u, v) in [0, 1] (row 0 = v 0); 0 outside."""
    h, w = decal.shape
    inside = (u >= 0) & (u < 1) & (v >= 0) & (v < 1)
    out = np.zeros(u.shape, np.float32)
    out[inside] = decal[(v[inside] * h).astype(int), (u[inside] * w).astype(int)]
    return out


def _frac(x):
    return x - np.floor(x)


class _Texels:
    """The covered texels of the atlas at rest: position ``p`` [N, 3] (and its ``x``, ``y``, ``z``), unit
    normal ``n`` [N, 3], limb coordinates ``arm_s`` / ``leg_s`` [N], garment label ``lab`` and body part
    label ``body_lab`` [N], and the colour ``col`` [N, 3] being painted (skin to start with)."""

    def __init__(self, look, rest, normals, faces, garments, body_face_labels, fid, bary):
        cov = fid >= 0
        f = fid[cov]
        w = bary[cov][..., None]
        tri = faces[f]
        self.p = (rest[tri] * w).sum(1)  # [N, 3] rest position of each covered texel
        n = (normals[tri] * w).sum(1)
        self.n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-9)
        self.arm_s = (garments.arm_s[tri] * w[..., 0]).sum(1)
        self.leg_s = (garments.leg_s[tri] * w[..., 0]).sum(1)
        self.lab = garments.face_labels[f]
        self.body_lab = np.asarray(body_face_labels)[f]
        self.x, self.y, self.z = self.p.T
        self.col = np.tile(look.skin, (len(self.p), 1))

    def paint(self, mask, colour, alpha=1.0) -> None:
        """Blend ``colour`` (one, or one per texel) over the texels of ``mask`` with ``alpha``."""
        a = np.broadcast_to(np.asarray(alpha, np.float64), mask.shape)[mask][:, None]
        colour = np.asarray(colour, np.float64)
        if colour.ndim == 2:  # one colour per texel
            colour = colour[mask]
        self.col[mask] = self.col[mask] * (1 - a) + colour * a


def bake_texture(
    look: Look,
    rest: np.ndarray,
    normals: np.ndarray,
    faces: np.ndarray,
    face_uvs: np.ndarray,
    garments: Garments,
    body_face_labels: np.ndarray,
    body_label_names: tuple[str, ...],
    size: int = 2048,
) -> np.ndarray:
    """Paint the texture atlas [size, size, 3] uint8 for ``faces``/``face_uvs`` of the rest mesh."""
    fid, bary = rasterize_uv(face_uvs, size)
    cov = fid >= 0
    t = _Texels(look, rest, normals, faces, garments, body_face_labels, fid, bary)
    lm = garments.landmarks
    _paint_skin(t, look, lm, list(body_label_names))
    _paint_hair(t, look, lm)
    _paint_top(t, look, lm)
    _paint_trousers(t, look, lm)
    _paint_shoes(t, look, lm)
    tex = np.zeros((size, size, 3), np.float32)
    tex[cov] = t.col
    tex = dilate(tex, cov, iterations=6)
    return np.clip(np.rint(tex * 255), 0, 255).astype(np.uint8)


def _paint_skin(t: _Texels, look: Look, lm: dict, names: list[str]) -> None:
    """Skin: faint blotches, brows, lips, eyes."""
    x, z, lab, n = t.x, t.z, t.lab, t.n
    t.paint(lab == SKIN, look.skin * 0.9, 0.5 * (_frac(np.sin(x * 91 + z * 57) * 43758.5) > 0.5) * 0.2)
    head_c = lm["head_c"]
    front = n[:, 1] < -0.3
    brow = (
        (lab == SKIN)
        & front
        & (np.abs(z - (head_c[2] + 0.105)) < 0.007)
        & (np.abs(np.abs(x) - 0.032) < 0.022)
    )
    t.paint(brow, look.hair * 0.8)
    lips = (lab == SKIN) & front & (np.abs(z - (head_c[2] + 0.015)) < 0.008) & (np.abs(x) < 0.024)
    t.paint(lips, np.array([0.70, 0.25, 0.28]), 0.8)
    for side in ("L", "R"):
        name = f"eye_front.{side}"
        if name in names:
            eye = t.body_lab == names.index(name)
            if eye.any():
                c = np.array([np.median(x[eye]), t.p[eye, 1].min(), np.median(z[eye])])
                r = np.hypot(x[eye] - c[0], z[eye] - c[2])
                t.col[eye] = np.where(
                    (r < 0.0035)[:, None],
                    0.05,
                    np.where((r < 0.0075)[:, None], np.array([0.30, 0.20, 0.10]), 0.95),
                )
    for name in ("mouth_cavity", "tongue", "eye_cavity.L", "eye_cavity.R"):
        if name in names:
            t.paint(t.body_lab == names.index(name), np.array([0.35, 0.12, 0.12]))


def _paint_hair(t: _Texels, look: Look, lm: dict) -> None:
    """Hair: base colour with fine strands running down the head."""
    head_c = lm["head_c"]
    strands = 0.75 + 0.25 * np.sin(np.arctan2(t.x - head_c[0], t.y - head_c[1]) * 160 + 3 * np.sin(t.z * 90))
    t.paint(t.lab == HAIR, look.hair * strands[:, None])


def _paint_top(t: _Texels, look: Look, lm: dict) -> None:
    """Shirt (and collar, hood): stripes + pinstripes, seams, cuffs, hem, prints."""
    x, z, lab, n, arm_s, paint = t.x, t.z, t.lab, t.n, t.arm_s, t.paint
    top = np.isin(lab, [SHIRT, COLLAR, HOOD])
    stripes = _frac(z / look.stripe_period) < 0.4
    paint(top, look.shirt)
    paint(top & stripes, look.stripe)
    paint(top & (_frac(z / 0.007) < 0.18), look.shirt * 0.55, 0.6)
    side_seam = top & (np.abs(n[:, 1]) < 0.10) & (arm_s < 0) & (np.abs(x) > 0.08)
    stitches = _frac(z / 0.012) < 0.55
    paint(side_seam, np.array([0.1, 0.1, 0.1]))
    paint(side_seam & stitches, np.array([0.95, 0.95, 0.95]))
    cuff = top & (arm_s > lm["sleeve_end"] - 0.07)
    paint(cuff, look.stripe * 0.6)
    paint(cuff & (_frac(arm_s * 120) < 0.3), np.array([0.95, 0.95, 0.95]))
    shoulder = top & (np.abs(arm_s - 0.08) < 0.012)
    paint(shoulder, np.array([0.1, 0.1, 0.1]))
    hem = top & (z < lm["hem_z"] + 0.025) & (arm_s < 0)
    paint(hem, look.shirt * 0.45)
    paint(np.isin(lab, [COLLAR]), look.stripe * 0.5)
    paint(lab == HOOD, look.shirt * 0.8)
    paint((lab == HOOD) & (_frac(x / 0.012) < 0.25), look.stripe * 0.5)
    chest = top & (n[:, 1] < -0.35) & (arm_s < 0)
    logo = _decal(look.word, logo=True)
    a = _sample(logo, (x + 0.10) / 0.20, (lm["chest_z"] + 0.05 - z) / 0.10)
    ink = np.full(3, 0.97) if look.shirt.sum() < 1.5 else np.full(3, 0.08)  # contrast with the shirt
    paint(chest, ink, a)
    back = top & (n[:, 1] > 0.35) & (arm_s < 0) & (lab != HOOD)
    num = _decal(f"{look.number:02d}", logo=False)
    a = _sample(num, (0.09 - x) / 0.18, (lm["chest_z"] + 0.0 - z) / 0.09)
    paint(back, look.stripe * 0.4 if look.stripe.sum() > 1.2 else np.array([0.97, 0.97, 0.97]), a)


def _paint_trousers(t: _Texels, look: Look, lm: dict) -> None:
    """Trousers: a check (tartan-like) pattern, a side stripe, a waistband."""
    x, z, n, paint = t.x, t.z, t.n, t.paint
    pants = t.lab == TROUSERS
    paint(pants, look.trousers)
    bx = _frac(x / look.check_period) < 0.22
    bz = _frac(z / look.check_period) < 0.22
    paint(pants & (bx | bz), look.check, 0.8)
    paint(pants & bx & bz, look.check * 0.5)
    paint(pants & (_frac((x + z) / 0.006) < 0.3), look.trousers * 0.6, 0.5)
    outer = pants & (t.leg_s >= 0) & (np.abs(n[:, 0]) > 0.93) & (np.sign(n[:, 0]) == np.sign(x))
    paint(outer, np.array([0.95, 0.95, 0.95]))
    paint(outer & (_frac(z / 0.02) < 0.3), look.check * 0.5)  # dashes along the stripe
    paint(pants & (np.abs(z - (lm["hip_z"] + 0.05)) < 0.018), look.trousers * 0.5)


def _paint_shoes(t: _Texels, look: Look, lm: dict) -> None:
    """Shoes: white uppers, dark sole, laces on top."""
    x = t.x
    shoe = t.lab == SHOES
    t.paint(shoe, look.shoes)
    t.paint(shoe & (t.z < lm["floor_z"] + 0.025), np.array([0.15, 0.15, 0.17]))
    laces = shoe & (t.n[:, 2] > 0.55) & (_frac(t.y / 0.014) < 0.35) & (np.abs(np.abs(x) - np.abs(x).mean()) < 1)
    t.paint(laces, look.check * 0.6)
