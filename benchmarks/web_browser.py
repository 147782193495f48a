"""Opening an exported avatar page in headless Chromium (Debian's ``chromium``, software WebGL) through
Playwright, for the web-export benchmark and tests: wait for ``window.gmaReady``, capture the view, read
the page's FPS."""

from __future__ import annotations

import base64
import contextlib
import re
import shutil
from collections.abc import Iterator
from pathlib import Path

import numpy as np

# SwiftShader is Chromium's software WebGL; a machine without a GPU gets it, and naming it keeps a GPU
# machine's figures comparable.
CHROMIUM_ARGS = ["--use-angle=swiftshader", "--enable-unsafe-swiftshader", "--ignore-gpu-blocklist"]
UI_HEIGHT = 48  # the control bar under a page exported with --size


def chromium_path() -> str | None:
    return shutil.which("chromium") or shutil.which("chromium-browser")


def missing_browser() -> str | None:
    """Why a page cannot be opened here (None when it can)."""
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "playwright is not installed (pip install -e .[dev])"
    if chromium_path() is None:
        return "Debian's chromium is not installed (scripts/install.sh as root, or apt-get install chromium)"
    return None


@contextlib.contextmanager
def browser() -> Iterator[object]:
    """A headless Chromium (a Playwright ``Browser``)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        b = p.chromium.launch(executable_path=chromium_path(), args=CHROMIUM_ARGS)
        try:
            yield b
        finally:
            b.close()


def open_page(b, page: Path, size: tuple[int, int], fragment: str = "", timeout_s: float = 120.0):
    """Load ``page`` (exported with ``--size`` ``size``) with the network cut off and wait until its first
    frame is drawn; raises RuntimeError with the page's error when it fails or asked for anything that is
    not in the file."""
    tab = b.new_page(viewport={"width": size[0], "height": size[1] + UI_HEIGHT})
    errors: list[str] = []
    tab.on("pageerror", lambda e: errors.append(str(e)))
    tab.route(re.compile(r"^(?!(file|data|blob):)"), lambda route: (errors.append(f"fetched {route.request.url}"),
                                                                     route.abort()))
    tab.goto(f"{Path(page).resolve().as_uri()}{fragment}")
    tab.wait_for_function("window.gmaReady === true || window.gmaError !== undefined", timeout=timeout_s * 1e3)
    if tab.evaluate("window.gmaError") or errors:
        raise RuntimeError(f"{page}: {tab.evaluate('window.gmaError') or errors[0]}")
    return tab


def capture(tab) -> np.ndarray:
    """[H, W, 3] uint8 of the page's view: the canvas's pixels, read between two of its frames (a
    screenshot would wait for the compositor, which a slow software frame can hold up for seconds)."""
    import imageio.v3 as iio

    url = tab.evaluate("document.getElementById('view').toDataURL('image/png')")
    return iio.imread(base64.b64decode(url.split(",", 1)[1]), extension=".png")[..., :3]


def page_fps(tab, frames: int = 4, timeout_s: float = 300.0) -> float:
    """Frames per second the page draws, timed by the page's clock over ``frames`` frames (after one
    settling frame): a software frame can take seconds, so a fixed window would count none."""
    tab.wait_for_function("window.gmaFrames >= 1", timeout=timeout_s * 1e3)
    start = tab.evaluate("[window.gmaFrames, performance.now()]")
    tab.wait_for_function(f"window.gmaFrames >= {start[0] + frames}", timeout=timeout_s * 1e3)
    end = tab.evaluate("[window.gmaFrames, performance.now()]")
    return (end[0] - start[0]) / ((end[1] - start[1]) / 1e3)
