"""Baking in texture space: which face (and where in it) each texel of a UV atlas belongs to, so that a
texture can be painted from 3D positions on the surface instead of raw UV coordinates (patterns then
stay continuous across UV seams), plus gutter filling so that bilinear lookups at seams do not bleed
in background colour."""

from __future__ import annotations

import numpy as np

__all__ = ["dilate", "rasterize_uv"]


def rasterize_uv(face_uvs: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Rasterise UV triangles into a ``size``×``size`` atlas (row 0 = v near 1, texel centres at +0.5).

    face_uvs: [F, 3, 2] per-corner (u, v) in [0, 1].
    Returns ``face_id`` int32 [S, S] (−1 where no face) and ``bary`` float32 [S, S, 3].

    Vectorised by grouping faces with the same bounding-box size, so each group is one array operation.
    """
    uv = np.asarray(face_uvs, np.float64)
    # Texel-space corners: x = u·S, y = (1 − v)·S; texel (i, j) has its centre at (j + .5, i + .5).
    px = np.stack([uv[..., 0] * size, (1.0 - uv[..., 1]) * size], axis=-1)
    lo = np.floor(px.min(axis=1) - 0.5).astype(np.int64)
    hi = np.ceil(px.max(axis=1) - 0.5).astype(np.int64)
    lo = np.clip(lo, 0, size - 1)
    hi = np.clip(hi, 0, size - 1)
    ext = hi - lo + 1  # [F, 2] bbox size in texels (x, y)
    face_id = np.full((size, size), -1, np.int32)
    bary = np.zeros((size, size, 3), np.float32)
    a, b, c = px[:, 0], px[:, 1], px[:, 2]
    det = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1])
    valid = np.abs(det) > 1e-12
    keys = ext[:, 0] * 100003 + ext[:, 1]
    for key in np.unique(keys[valid]):
        f = np.nonzero((keys == key) & valid)[0]
        ex, ey = ext[f[0]]
        gx, gy = np.meshgrid(np.arange(ex), np.arange(ey), indexing="xy")
        x = lo[f, 0, None] + gx.ravel()[None] + 0.5  # [n, ex·ey] texel centres
        y = lo[f, 1, None] + gy.ravel()[None] + 0.5
        d = det[f, None]
        w1 = (
            (x - a[f, 0, None]) * (c[f, 1, None] - a[f, 1, None])
            - (c[f, 0, None] - a[f, 0, None]) * (y - a[f, 1, None])
        ) / d
        w2 = (
            (b[f, 0, None] - a[f, 0, None]) * (y - a[f, 1, None])
            - (x - a[f, 0, None]) * (b[f, 1, None] - a[f, 1, None])
        ) / d
        w0 = 1.0 - w1 - w2
        inside = (w0 >= -1e-6) & (w1 >= -1e-6) & (w2 >= -1e-6)
        fi, ti = np.nonzero(inside)
        row = (y[fi, ti] - 0.5).astype(np.int64)
        col = (x[fi, ti] - 0.5).astype(np.int64)
        face_id[row, col] = f[fi]
        bary[row, col] = np.stack([w0[fi, ti], w1[fi, ti], w2[fi, ti]], axis=-1)
    return face_id, bary


def dilate(image: np.ndarray, covered: np.ndarray, iterations: int = 8) -> np.ndarray:
    """Fill uncovered texels from covered 4-neighbours, ``iterations`` texels deep (the gutter that
    keeps bilinear filtering at UV seams from mixing in empty texels)."""
    img = image.astype(np.float32).copy()
    cov = covered.copy()
    for _ in range(iterations):
        acc = np.zeros_like(img)
        cnt = np.zeros(cov.shape, np.float32)
        for axis, shift in ((0, 1), (0, -1), (1, 1), (1, -1)):
            m = np.roll(cov, shift, axis=axis)
            acc += np.roll(img, shift, axis=axis) * m[..., None]
            cnt += m
        grow = (~cov) & (cnt > 0)
        img[grow] = acc[grow] / cnt[grow][:, None]
        cov = cov | grow
    return img
