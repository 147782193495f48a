"""Person masks checked against the background, for a clip filmed from a fixed camera.

MediaPipe's person mask is a low-resolution probability map: its edges are soft and sometimes a few
pixels off, and it has holes where clothing looks like background to it (a dark jacket panel, a sleeve
across the torso). Both end up in the avatar, since the fit's targets are the frames composited over a
grey background through these masks: the avatar learns translucent patches and a grey halo.

With a fixed camera the background is known wherever the person is not, and a person turning in place
uncovers in one frame most of what they hide in another. So

1. the **background plate** is the per-pixel median of the frames in which that pixel lies well away from
   MediaPipe's person (``margin``); a pixel's plate is **known** when enough frames saw it and they agree
   (a moving camera, a flickering light or someone walking by makes them disagree);
2. in each frame (the plate first scaled per channel to the frame's exposure and white balance, from the
   background away from the person; a frame whose background still differs is left alone), near
   MediaPipe's person and where the plate is known, pixels that **clearly differ** from
   the plate (6 sigma of its own noise, and not a shadow: darker with the plate's hue) become person, which
   fills holes and restores cut-off edges; pixels MediaPipe gives less than one half that **match** the
   plate (within 3 sigma) become background, which removes the halo. Everything else keeps MediaPipe's value
   (a white shirt against a white wall, a shadow, a pixel the plate never saw);
3. person pixels added away from MediaPipe's person are dropped (a door that moved), and the inside of
   the person (``opaque_depth`` from its edge) is made opaque: MediaPipe's half-transparent patches lie
   mostly where the person always stands, where the plate knows nothing. (Filling enclosed holes there
   as well was tried: on the iPER clip it also closed the real gap between the legs.)

The worst case is MediaPipe's mask. A clip whose background moves (hand-held) is detected from the
plate's spread and left as it is, with the reason in the report.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MatteConfig", "background_plate", "refine_masks"]


@dataclass
class MatteConfig:
    margin: float = 0.04          # of the image height: how far from MediaPipe's person a pixel counts as plate
    min_views: float = 0.1        # share of the plate frames (at least 3) that must have seen a pixel
    max_spread: float = 0.06      # largest median |frame - plate| (0-1 colour) of a known pixel
    moving_spread: float = 0.05   # median spread over the image above which the camera counts as moving
    noise_floor: float = 0.02     # smallest sigma of a plate pixel's colour (compression, dithering)
    opaque_depth: float = 0.01    # of the image height: person pixels this far inside the mask are opaque
    plate_frames: int = 48        # at most this many frames, evenly spaced, build the plate
    chunk_rows: int = 32          # rows per block while building the plate (bounds memory)
    work_side: int = 1280         # longest side the check runs at; larger clips are shrunk by a whole factor


def _dilate(mask: np.ndarray, radius: int) -> np.ndarray:
    """Boolean ``mask`` [..., H, W] grown by a square of half-width ``radius`` (separable: fast)."""
    from scipy.ndimage import maximum_filter

    size = (1,) * (mask.ndim - 2) + (2 * radius + 1, 2 * radius + 1)
    return maximum_filter(mask.astype(np.uint8), size=size).astype(bool)


def _erode(mask: np.ndarray, radius: int) -> np.ndarray:
    """Pixels of boolean ``mask`` [H, W] whose whole square of half-width ``radius`` is in the mask."""
    return ~_dilate(~mask, radius)


def background_plate(frames: np.ndarray, masks: np.ndarray, cfg: MatteConfig | None = None):
    """The clip's background: (plate float32 [H, W, 3] in 0-1, views int [H, W]: how many of the plate
    frames saw the pixel as background, spread float32 [H, W]: their median absolute difference from the
    plate, mean over the channels; inf where none did). ``frames`` uint8 [T, H, W, 3], ``masks`` [T, H, W]
    person probabilities."""
    cfg = cfg or MatteConfig()
    T, H, W = masks.shape
    sel = np.unique(np.linspace(0, T - 1, min(T, cfg.plate_frames)).round().astype(int))
    person = _dilate(masks[sel] > 0.05, max(1, round(cfg.margin * H)))
    views = (~person).sum(0)
    plate = np.zeros((H, W, 3), np.float32)
    spread = np.full((H, W), np.inf, np.float32)
    for r0 in range(0, H, cfg.chunk_rows):
        rows = slice(r0, min(H, r0 + cfg.chunk_rows))
        seen = ~person[:, rows]
        if not seen.any():
            continue
        samples = np.where(seen[..., None], frames[sel, rows].astype(np.float32) / 255.0, np.nan)
        block = _nanmedian0(samples)
        dev = _nanmedian0(np.abs(samples - block[None])).mean(-1)
        plate[rows] = np.nan_to_num(block)
        spread[rows] = np.where(views[rows] > 0, dev, np.inf)
    return plate, views, spread


def _nanmedian0(x: np.ndarray) -> np.ndarray:
    """``np.nanmedian(x, axis=0)`` (NaN where no value), the same numbers: one sort (NaNs go last) and the
    middle of each column's values. numpy's own takes masked arrays for a short axis, which is far slower."""
    k = (~np.isnan(x)).sum(0)
    s = np.sort(x, axis=0)
    lo = np.take_along_axis(s, np.maximum((k - 1) // 2, 0)[None], 0)[0]
    hi = np.take_along_axis(s, np.minimum(k // 2, len(x) - 1)[None], 0)[0]
    return np.where(k > 0, (lo + hi) / np.float32(2), np.float32(np.nan))


def _colour_test(frame: np.ndarray, plate: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(clearly not the plate, the plate's colour) per pixel of ``frame`` uint8 [H, W, 3]."""
    img = frame.astype(np.float32) / 255.0
    diff = np.sqrt(((img - plate) ** 2).mean(-1))
    lum_i, lum_p = img.mean(-1), np.maximum(plate.mean(-1), 1e-3)
    ratio = lum_i / lum_p
    chroma = np.abs(img / np.maximum(lum_i, 1e-3)[..., None] - plate / lum_p[..., None]).max(-1)
    # A shadow (the person's, on the floor or a wall behind) darkens the plate and keeps its hue. A dark
    # grey sleeve in front of a white wall keeps the hue too, but darkens far more (ratio well below 0.5).
    shadow = (ratio > 0.5) & (ratio < 1.0) & (chroma < 0.12)
    return (diff > 6.0 * sigma) & ~shadow, diff < 3.0 * sigma


def _frame_plate(frame: np.ndarray, plate: np.ndarray, far: np.ndarray, cfg: MatteConfig):
    """The plate as this frame's exposure and white balance show it: scaled per channel by the median ratio
    of the frame to the plate over ``far`` (known background away from the person). None when too little
    background is visible or it still differs after that (lights changed, the camera moved once)."""
    if far.sum() < 64:
        return None
    img = frame[far].astype(np.float32) / 255.0
    ref = plate[far]
    # Ratios only where the plate is bright enough to have one: the black bars of a letterboxed or
    # pillarboxed clip (0 / 0) would otherwise set the median, the gain would drop to its floor and the
    # whole lit background near the person would read as person (a 1080p pillarboxed clip: 53 % of the
    # person's area added, halos around the arms).
    gain = np.ones(3, np.float32)
    for c in range(3):
        lit = ref[:, c] > 0.08
        if lit.sum() >= 64:
            gain[c] = np.median(img[lit, c] / ref[lit, c])
    gain = np.clip(gain, 0.5, 2.0)
    adjusted = np.clip(plate * gain, 0.0, 1.0)
    if np.median(np.sqrt(((img - adjusted[far]) ** 2).mean(-1))) > cfg.moving_spread:
        return None
    return adjusted


# What the check decides per pixel (``_refine_frame``): MediaPipe's value stays, or the pixel becomes person or
# background. Decisions rather than a mask, so that a check made on shrunk frames applies to the full ones.
KEEP, PERSON, BACKGROUND = 0, 1, 2


def _refine_frame(frame, mask, plate, known, sigma, radius, inner, cfg):
    """One frame's decisions (int8 [H, W] of KEEP / PERSON / BACKGROUND), or None when the frame does not
    match the plate."""
    from scipy.ndimage import label

    near = _dilate(mask > 0.05, radius) & known
    plate = _frame_plate(frame, plate, known & ~near, cfg)
    if plate is None:
        return None
    differs, matches = _colour_test(frame, plate, sigma)
    decision = np.zeros(mask.shape, np.int8)
    decision[near & differs] = PERSON
    decision[near & matches & (mask < 0.5)] = BACKGROUND
    # Person pixels added away from MediaPipe's person go back (a door that moved, a passer-by).
    fg = (decision == PERSON) | ((decision == KEEP) & (mask > 0.5))
    labels, n = label(fg)
    if n:
        touching = np.zeros(n + 1, bool)
        touching[labels[(mask > 0.5) & fg]] = True
        touching[0] = True
        decision[~touching[labels]] = KEEP
        fg &= touching[labels]
    # The inside of a person is opaque: MediaPipe's soft patches there (a jacket panel it half-missed,
    # mostly where the person always stands and the plate knows nothing) become person.
    decision[_erode(fg, inner)] = PERSON
    return decision


def _apply(mask: np.ndarray, decision: np.ndarray, f: int) -> np.ndarray:
    """``mask`` with the check's ``decision``, made on the mask shrunk by ``f`` (``_shrink``): each decision
    covers its f x f block; background only where MediaPipe said below one half, as on the shrunk mask."""
    if f > 1:
        decision = np.repeat(np.repeat(decision, f, 0), f, 1)[: mask.shape[0], : mask.shape[1]]
    out = mask.copy()
    out[decision == PERSON] = 1.0
    out[(decision == BACKGROUND) & (mask < 0.5)] = 0.0
    return out


def _shrink(a: np.ndarray, f: int) -> np.ndarray:
    """``a`` [H, W, ...] averaged over f x f blocks (edges repeated to whole blocks), in ``a``'s dtype."""
    if f == 1:
        return a
    H, W = a.shape[:2]
    a = np.pad(a, ((0, -H % f), (0, -W % f)) + ((0, 0),) * (a.ndim - 2), mode="edge")
    total = np.zeros((a.shape[0] // f, a.shape[1] // f, *a.shape[2:]), np.float32)
    for i in range(f):  # f x f strided adds: far faster than a mean over the axes of a reshaped array
        for j in range(f):
            total += a[i::f, j::f]
    total /= f * f
    return total.round().astype(a.dtype) if a.dtype == np.uint8 else total.astype(a.dtype)


def refine_masks(frames: np.ndarray, masks: np.ndarray, cfg: MatteConfig | None = None,
                 progress: bool = False) -> tuple[np.ndarray, dict]:
    """``masks`` float32 [T, H, W] checked against the clip's background plate (module docstring), and a
    report: whether it was applied (else why not), the share of the person's surroundings whose background
    is known, and the share of the person's area added and removed."""
    cfg = cfg or MatteConfig()
    frames = np.asarray(frames)
    masks = np.asarray(masks, np.float32)  # (no copy of MediaPipe's: a long 1080p clip's masks take GBs)
    if masks.ndim != 3 or frames.shape != (*masks.shape, 3):
        raise ValueError(f"frames {frames.shape} do not match masks {masks.shape}")
    if not (masks.min(initial=0.0) >= 0.0 and masks.max(initial=0.0) <= 1.0):  # NaN fails too
        raise ValueError("masks must be probabilities in [0, 1]")
    T, H, W = masks.shape
    report: dict = {"applied": False}
    if T < 3:
        report["reason"] = f"{T} frames: too few to see the background behind the person"
        return masks, report
    # A phone's 4K frames are checked shrunk (by 3: 1280 x 720), the decisions applied to the full masks:
    # MediaPipe's masks are upsampled from far less than that, and a full-size check at 4K is slow.
    f = -(-max(H, W) // cfg.work_side)
    small_frames = frames if f == 1 else np.stack([_shrink(fr, f) for fr in frames])
    small_masks = masks if f == 1 else np.stack([_shrink(m, f) for m in masks])
    checked = _check(small_frames, small_masks, cfg, report, progress)
    if checked is None:
        return masks, report
    decisions, known_near_person = checked
    out = np.empty_like(masks)  # the one full-size copy
    unmatched = area = added = removed = 0
    for t, decision in enumerate(decisions):
        unmatched += decision is None
        out[t] = masks[t] if decision is None else _apply(masks[t], decision, f)
        before, after = masks[t] > 0.5, out[t] > 0.5  # a frame at a time: 4K masks are 8 MB each
        area, added, removed = area + before.sum(), added + (after & ~before).sum(), removed + (before & ~after).sum()
    area = max(int(area), 1)
    report.update(applied=True,
                  known_background_near_person=round(known_near_person, 4),
                  person_area_added=round(float(added) / area, 4),
                  person_area_removed=round(float(removed) / area, 4),
                  frames_left_as_estimated=unmatched,
                  checked_at_size=[int(small_masks.shape[2]), int(small_masks.shape[1])])
    return out, report


def _check(frames: np.ndarray, masks: np.ndarray, cfg: MatteConfig, report: dict, progress: bool):
    """(each frame's decisions, None for a frame that does not match the plate; the share of the person's
    surroundings whose background is known), or None, with the reason in ``report``, when the clip's
    background cannot be used."""
    from tqdm import tqdm

    T, H, W = masks.shape
    plate, views, spread = background_plate(frames, masks, cfg)
    seen = views >= 3
    if not seen.any():
        report["reason"] = "no pixel was background in three frames"
        return None
    moving = float(np.median(spread[seen]))
    report["background_spread_median"] = round(moving, 4)
    if moving > cfg.moving_spread:
        report["reason"] = (f"the background changes between frames (median spread {moving:.3f} > "
                            f"{cfg.moving_spread}): the camera moves; masks left as estimated")
        return None
    known = (views >= max(3, cfg.min_views * min(T, cfg.plate_frames))) & (spread <= cfg.max_spread)
    sigma = np.maximum(cfg.noise_floor, 1.4826 * np.where(known, spread, 0.0)).astype(np.float32)
    radius = max(1, round(cfg.margin * H))
    inner = max(1, round(cfg.opaque_depth * H))
    around = _dilate((masks > 0.05).any(0), radius)
    decisions = [_refine_frame(frames[t], masks[t], plate, known, sigma, radius, inner, cfg)
                 for t in tqdm(range(T), desc="masks", unit="frame", disable=not progress, leave=False)]
    return decisions, float(known[around].mean())
