"""``gma export avatar.gma page.html``: the page's data (skin weights, bones, the self-contained HTML), and
in headless Chromium a frame that matches ``gma render`` and playback that moves."""

from __future__ import annotations

import base64
import gzip
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest
from edit_helpers import varied_avatar

from gma.cli import main as gma_main

REPO = Path(__file__).resolve().parents[1]
VIEW = (256, 256)


@pytest.fixture(scope="module")
def avatar_file(tmp_path_factory, anny_body):
    """A small avatar with varied colours, scales and offsets (random decoder weights), saved."""
    return varied_avatar(anny_body).save(tmp_path_factory.mktemp("web") / "a.gma")


def _rotations(quats_xyzw: np.ndarray) -> np.ndarray:
    """[..., 3, 3] from unit quaternions (x, y, z, w) [..., 4]."""
    x, y, z, w = np.moveaxis(quats_xyzw.astype(np.float64), -1, 0)
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1).reshape(
        *quats_xyzw.shape[:-1], 3, 3)


def test_skin_packing_is_sparks_layout():
    from gma.export.web import pack_skin

    idx = np.array([[3, 7, 0, 1], [103, 2, 5, 6]])
    w = np.array([[0.5, 0.3, 0.2, 0.0], [0.334, 0.333, 0.333, 0.0]])
    packed = pack_skin(idx, w)
    assert packed.dtype == np.uint16
    assert ((packed >> 8) == idx).all()
    assert ((packed & 255).sum(1) == 255).all()  # the rounding error goes to the strongest bone


def test_skinned_centres_follow_gmas_posing(avatar_file, anny_body):
    """Rest centres moved by the page's bones and 8-bit weights land where GMA places the surfels."""
    from gma.avatar import Avatar
    from gma.body.motions import motion
    from gma.export import posed_splats
    from gma.export.web import motion_bones, skinned_splats

    avatar = Avatar.load(avatar_file)
    rest = skinned_splats(avatar, anny_body)
    walk = motion("walk", 30, anny_body)
    bones = motion_bones(avatar, anny_body, walk)
    assert bones.shape == (30, anny_body.num_bones, 7)
    weights, idx = (rest.skin & 255) / 255.0, rest.skin >> 8
    for t in (0, 17):
        want = posed_splats(avatar, anny_body, {"pose": walk.params(t)["pose"]})["means"]
        rot, shift = _rotations(bones[t, :, :4]), bones[t, :, 4:]
        got = sum(weights[:, k:k + 1] * (np.einsum("nij,nj->ni", rot[idx[:, k]], rest.means) + shift[idx[:, k]])
                  for k in range(4))
        err = np.linalg.norm(got - want, axis=1)
        assert err.mean() < 1e-3 and np.percentile(err, 99) < 1e-2, (t, err.mean(), np.percentile(err, 99))


def test_page_holds_everything_it_plays(avatar_file, anny_body):
    """One file: the player inline, the data inline (gzip + base64), nothing fetched from elsewhere."""
    from gma.avatar import Avatar
    from gma.body.motions import motion
    from gma.export.web import PageCamera, motion_bones, page_html, skinned_splats

    avatar = Avatar.load(avatar_file)
    splats = skinned_splats(avatar, anny_body)
    walk, turn = motion("walk", 12, anny_body), motion("turn", 9, anny_body)
    tracks = [(m.name, m, motion_bones(avatar, anny_body, m)) for m in (walk, turn)]
    camera = PageCamera((0, -3, 1), (0, 0, 1), (0, 0, 1), 40.0)
    page = page_html("<me>", splats, tracks, camera, "console.log('</script>')", (320, 240))
    assert "<title>&lt;me&gt;</title>" in page and "width:320px;height:240px" in page
    assert not re.search(r"""(src|href)\s*=\s*["']?(https?:)?//""", page)
    assert page.count("</script>") == 3  # meta, data, player: the player's own "</script" is escaped
    meta = json.loads(re.search(r'id="gma-meta">(.*?)</script>', page, re.S).group(1))
    blob = gzip.decompress(base64.b64decode(re.search(r'id="gma-data">(.*?)</script>', page, re.S).group(1)))
    assert meta["numSplats"] == len(splats.means) and [m["frames"] for m in meta["motions"]] == [12, 9]

    def array(spec, dtype):
        return np.frombuffer(blob, dtype, int(np.prod(spec["shape"])), spec["offset"]).reshape(spec["shape"])

    np.testing.assert_array_equal(array(meta["arrays"]["means"], np.float32), splats.means)
    np.testing.assert_array_equal(array(meta["arrays"]["skin"], np.uint16), splats.skin)
    np.testing.assert_array_equal(array(meta["motions"][1]["bones"], np.float32), tracks[1][2])


def test_unbuilt_player_is_one_line(avatar_file, tmp_path, monkeypatch, capsys):
    """Without node/npm the player is not built: the export says so, exit 2, nothing written."""
    from gma.export import web

    monkeypatch.setattr(web, "BUNDLE", tmp_path / "web" / "dist" / "gma-page.js")
    out = tmp_path / "a.html"
    assert gma_main(["export", str(avatar_file), str(out), "--motion", "walk"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "npm" in err[0] and "gma-page.js" in err[0]
    assert not out.exists()


# -- in a browser ---------------------------------------------------------------------------------------
def _browser_or_skip():
    from gma.export.web import BUNDLE

    sys.path.insert(0, str(REPO / "benchmarks"))
    import web_browser

    why = web_browser.missing_browser()
    if why is None and not BUNDLE.is_file():
        why = f"{BUNDLE} is not built (scripts/install.sh needs node and npm)"
    if why:
        pytest.skip(why)
    return web_browser


@pytest.fixture(scope="module")
def page(avatar_file, tmp_path_factory):
    _browser_or_skip()
    out = tmp_path_factory.mktemp("page") / "a.html"
    assert gma_main(["export", str(avatar_file), str(out), "--motion", "walk", "--motion", "turn",
                     "--size", f"{VIEW[0]}x{VIEW[1]}"]) == 0
    return out


@pytest.mark.slow
def test_page_frame_matches_gma_render(page, avatar_file, gpu):
    """A paused moment of the page (``#t=``) against `gma render` of that frame from the page's camera."""
    wb = _browser_or_skip()
    sys.path.insert(0, str(REPO / "benchmarks"))
    from web_export import box_psnr, gma_frames

    reference = gma_frames(avatar_file, "walk", (30,), VIEW)[0]
    with wb.browser() as b:
        tab = wb.open_page(b, page, VIEW, "#t=1.0")
        assert tab.evaluate("window.gmaPlayer.playing") is False
        shot = wb.capture(tab)
    assert shot.shape == reference.shape
    assert box_psnr(shot, reference) >= 25.0


@pytest.mark.slow
def test_page_plays_the_motion(page):
    """Playing, the time advances and the picture changes; the picker switches motion; paused, a drag
    turns the view."""
    wb = _browser_or_skip()
    with wb.browser() as b:
        tab = wb.open_page(b, page, VIEW)
        assert tab.evaluate("window.gmaPlayer.playing") is True
        first, t0 = wb.capture(tab), tab.evaluate("window.gmaPlayer.time")
        tab.wait_for_function(f"window.gmaPlayer.time > {t0} + 0.5", timeout=60_000)
        frames = tab.evaluate("window.gmaFrames")
        tab.wait_for_function(f"window.gmaFrames > {frames} + 1", timeout=60_000)
        assert np.abs(wb.capture(tab).astype(int) - first).max() > 64
        assert tab.locator("#motion option").all_inner_texts() == ["walk", "turn"]
        tab.select_option("#motion", "1")
        assert tab.evaluate("window.gmaPlayer.index") == 1
        tab.click("#play")
        assert tab.evaluate("window.gmaPlayer.playing") is False
        _next_frames(tab)
        still = wb.capture(tab)
        tab.mouse.move(VIEW[0] / 2, VIEW[1] / 2)  # a drag orbits the view
        tab.mouse.down()
        tab.mouse.move(VIEW[0] / 2 + 80, VIEW[1] / 2, steps=4)
        tab.mouse.up()
        _next_frames(tab)
        assert np.abs(wb.capture(tab).astype(int) - still).max() > 64


def _next_frames(tab, count: int = 2) -> None:
    frames = tab.evaluate("window.gmaFrames")
    tab.wait_for_function(f"window.gmaFrames >= {frames + count}", timeout=60_000)
