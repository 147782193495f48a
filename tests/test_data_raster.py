"""Textured-mesh rasteriser (wgpu render pipeline) on tiny scenes with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from gma.core.camera import projection_matrix
from gma.synth.mesh_raster import MeshRasterizer, TexturedMesh

pytestmark = pytest.mark.gpu

W, H = 16, 12
K = np.array([[10.0, 0, 0], [0, 10.0, 0], [0, 0, 1]])  # principal point at the image corner: x_pix = 10 x / z


def quad(x0, y0, x1, y1, z):
    """A quad whose projection covers pixel rectangle [x0, x1) × [y0, y1) at depth z (camera = world)."""
    corners = np.array([[x0, y1], [x1, y1], [x1, y0], [x0, y0]], np.float64) / 10.0 * z
    v = np.column_stack([corners, np.full(4, z)])
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)  # v up: corner 3 (top row) has v = 1
    return v, faces, uv[faces]


def split_texture():
    tex = np.zeros((8, 8, 3), np.uint8)
    tex[:4] = (255, 0, 0)  # top rows of the image = v near 1
    tex[4:] = (0, 0, 255)
    return tex


def render(gpu, v, faces, face_uvs, tex, ss=4):
    r = MeshRasterizer(gpu, TexturedMesh(faces, face_uvs, tex), W, H, supersample=ss, shading=0.0)
    return r.render(v, K, np.eye(4), background=(0, 1, 0))


def test_pixel_exact_coverage(gpu):
    v, f, uv = quad(2, 3, 9, 7, z=2.0)
    img, mask = render(gpu, v, f, uv, np.full((2, 2, 3), 200, np.uint8))
    want = np.zeros((H, W), np.float32)
    want[3:7, 2:9] = 1
    np.testing.assert_allclose(mask, want, atol=1e-6)
    assert (img[mask == 1] == 200).all() and (img[mask == 0] == (0, 255, 0)).all()


def test_half_pixel_edge_is_soft(gpu):
    v, f, uv = quad(2.5, 3, 9, 7, z=2.0)
    _, mask = render(gpu, v, f, uv, np.full((2, 2, 3), 200, np.uint8), ss=4)
    np.testing.assert_allclose(mask[4, 2], 0.5, atol=1e-6)


def test_texture_orientation(gpu):
    v, f, uv = quad(0, 0, W, H, z=1.0)
    img, _ = render(gpu, v, f, uv, split_texture())
    assert tuple(img[1, W // 2]) == (255, 0, 0)  # top of the image shows the top of the texture
    assert tuple(img[H - 2, W // 2]) == (0, 0, 255)


def test_depth_order_and_determinism(gpu):
    va, fa, uva = quad(0, 0, 10, 10, z=3.0)
    vb, fb, uvb = quad(5, 5, 16, 12, z=2.0)
    v = np.vstack([va, vb])
    f = np.vstack([fa, fb + 4])
    uv = np.concatenate([uva * [0.2, 1], uvb * [0.2, 1] + [0.8, 0]])  # left column of texture vs right
    tex = np.zeros((2, 8, 3), np.uint8)
    tex[:, :2] = (255, 255, 255)
    tex[:, 6:] = (0, 0, 0)
    img1, m1 = render(gpu, v, f, uv, tex)
    img2, m2 = render(
        gpu,
        v[[4, 5, 6, 7, 0, 1, 2, 3]],
        np.vstack([fb, fa + 4]),
        np.concatenate([uvb * [0.2, 1] + [0.8, 0], uva * [0.2, 1]]),
        tex,
    )
    assert tuple(img1[7, 7]) == (0, 0, 0) and tuple(img1[2, 2]) == (255, 255, 255)
    np.testing.assert_array_equal(img1, img2)
    again, _ = render(gpu, v, f, uv, tex)
    np.testing.assert_array_equal(img1, again)


def test_projection_matches_K():
    Kx = np.array([[300.0, 0, 120], [0, 310, 90], [0, 0, 1]])
    P = projection_matrix(Kx, 256, 200)
    x = np.array([0.3, -0.2, 2.5, 1.0])
    c = P @ x
    ndc = c[:3] / c[3]
    pix = Kx @ x[:3] / x[2]
    np.testing.assert_allclose([(ndc[0] + 1) / 2 * 256, (1 - ndc[1]) / 2 * 200], pix[:2], atol=1e-9)
    assert 0 < ndc[2] < 1


def test_empty_and_bad_input(gpu):
    r = MeshRasterizer(
        gpu, TexturedMesh(np.zeros((0, 3), int), np.zeros((0, 3, 2)), np.zeros((1, 1, 3), np.uint8)), W, H
    )
    img, mask = r.render(np.zeros((0, 3)), K, np.eye(4))
    assert mask.max() == 0 and img.shape == (H, W, 3)
    with pytest.raises(ValueError, match="face_uvs"):
        TexturedMesh(np.zeros((2, 3), int), np.zeros((1, 3, 2)), np.zeros((1, 1, 3), np.uint8))
