"""What a video import reports: reprojection error, mask IoU of the fitted body, and a contact sheet of
the fitted body drawn over the frames, so a user can judge the fit before training on it."""

from __future__ import annotations

import numpy as np
from PIL import Image, ImageDraw

__all__ = ["contact_sheet", "mask_iou", "overlay", "project_vertices", "reprojection_errors", "silhouette"]


def project_vertices(vertices: np.ndarray, K: np.ndarray, w2c: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pixels [V, 2] and camera depth [V] of world vertices [V, 3]."""
    cam = vertices @ w2c[:3, :3].T + w2c[:3, 3]
    z = np.maximum(cam[:, 2], 1e-3)
    uv = cam[:, :2] / z[:, None] * np.array([K[0, 0], K[1, 1]]) + np.array([K[0, 2], K[1, 2]])
    return uv, cam[:, 2]


def silhouette(uv: np.ndarray, faces: np.ndarray, width: int, height: int) -> np.ndarray:
    """Binary mask bool [H, W] of the triangles ``faces`` [F, 3] with corners at pixels ``uv`` [V, 2]."""
    img = Image.new("1", (width, height), 0)
    draw = ImageDraw.Draw(img)
    for tri in uv[faces]:
        draw.polygon([tuple(p) for p in tri], fill=1)
    return np.asarray(img, bool)


def mask_iou(a: np.ndarray, b: np.ndarray) -> float:
    """Intersection over union of two bool masks (1.0 when both are empty)."""
    union = np.logical_or(a, b).sum()
    return float(np.logical_and(a, b).sum() / union) if union else 1.0


def reprojection_errors(uv: np.ndarray, target: np.ndarray, conf: np.ndarray, min_conf: float = 0.5) -> np.ndarray:
    """Mean pixel distance per frame [T] between fitted points uv [T, P, 2] and landmarks target
    [T, P, 2] where conf [T, P] ≥ ``min_conf`` (NaN for frames with none)."""
    err = np.linalg.norm(uv - target, axis=-1)
    ok = conf >= min_conf
    with np.errstate(invalid="ignore"):
        return np.where(ok.any(1), (err * ok).sum(1) / np.maximum(ok.sum(1), 1), np.nan)


def overlay(image: np.ndarray, uv: np.ndarray, depth: np.ndarray, faces: np.ndarray,
            points: np.ndarray | None = None, alpha: float = 0.55) -> np.ndarray:
    """The frame with the fitted mesh drawn over it, shaded by facing (painter's algorithm, far faces
    first), and optional landmark points [P, 2] as red dots. uint8 [H, W, 3]."""
    h, w = image.shape[:2]
    tri = uv[faces]
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    facing = -(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])  # screen-space winding: > 0 faces the camera
    keep = facing > 0
    order = np.argsort(-depth[faces].mean(1)[keep])
    area = np.abs(facing[keep][order])
    shade = np.clip(0.35 + 0.65 * np.sqrt(area / (np.percentile(area, 90) + 1e-9)), 0, 1)
    layer = Image.new("RGB", (w, h), (0, 0, 0))
    cover = Image.new("L", (w, h), 0)
    d, dc = ImageDraw.Draw(layer), ImageDraw.Draw(cover)
    for t, s in zip(tri[keep][order], shade):
        pts = [tuple(p) for p in t]
        d.polygon(pts, fill=(int(90 * s), int(200 * s), int(255 * s)))
        dc.polygon(pts, fill=255)
    a = np.asarray(cover, np.float32)[..., None] / 255 * alpha
    out = (image.astype(np.float32) * (1 - a) + np.asarray(layer, np.float32) * a).astype(np.uint8)
    if points is not None:
        img = Image.fromarray(out)
        dr = ImageDraw.Draw(img)
        r = max(1.5, w / 200)
        for x, y in points:
            if np.isfinite(x) and np.isfinite(y):
                dr.ellipse([x - r, y - r, x + r, y + r], fill=(255, 40, 40))
        out = np.asarray(img)
    return out


def contact_sheet(tiles: list[np.ndarray], columns: int = 4, tile_width: int = 256) -> np.ndarray:
    """Tiles uint8 [H, W, 3] resized to ``tile_width`` and laid out in a grid. uint8 [H', W', 3]."""
    if not tiles:
        raise ValueError("contact sheet needs at least one tile")
    h, w = tiles[0].shape[:2]
    th = max(1, round(h * tile_width / w))
    rows = (len(tiles) + columns - 1) // columns
    sheet = np.full((rows * th, min(columns, len(tiles)) * tile_width, 3), 255, np.uint8)
    for i, t in enumerate(tiles):
        small = np.asarray(Image.fromarray(t).resize((tile_width, th), Image.Resampling.BILINEAR))
        r, c = divmod(i, columns)
        sheet[r * th:(r + 1) * th, c * tile_width:(c + 1) * tile_width] = small
    return sheet
