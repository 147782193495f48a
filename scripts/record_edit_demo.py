"""Scripted screen recording of the viewer's edit tools: a paint stroke, a mirrored stroke (X), a stamp and
a transfer, driven
through the window's own mouse and keyboard callbacks (the code paths a person's input takes), captured
from the window's surface and written as a GIF.

    python scripts/record_edit_demo.py docs/viewer_edit.gif      # starts Xvfb when there is no DISPLAY

The avatar is made here (no fitted avatar is needed): a fresh one whose regions are painted with
gma.edit (skin, shirt, trousers, shoes) so that it reads as a person; the donor is a copy of it with
another shirt.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from viewer.display import ensure_display  # noqa: E402


def make_avatars(folder: Path, fine_per_face: int):
    """(avatar.gma, donor.gma, stamp.png) in ``folder``."""
    import imageio.v3 as iio
    import numpy as np
    import torch

    from gma.avatar import Avatar
    from gma.avatar.config import AvatarConfig
    from gma.body import load_body
    from gma.edit import Editor, Selection, solid_shape

    body = load_body("anny")
    av = Avatar.create(AvatarConfig(feature_dim=16, fine_per_face=fine_per_face), body)
    ed = Editor(av, body)
    regions = Selection.from_regions
    ed.paint(regions(body, "head", "arms", "hands"), "#d9a98c")
    ed.paint(regions(body, "torso"), "#3a5f9f")
    ed.paint(regions(body, "legs"), "#3b3b46")
    ed.paint(regions(body, "feet"), "#20201e")
    av.history.clear()  # the demo starts from this look
    av.save(folder / "avatar.gma")
    donor = Avatar.load(folder / "avatar.gma", body)
    ded = Editor(donor, body)
    torso = regions(body, "torso")
    ded.paint(torso, "#e8c53a")
    # Horizontal stripes on the donor's shirt (by face-centre height), so the transfer is easy to see.
    with torch.no_grad():
        verts = body.rest_vertices(body.canonical_params(donor.shape))
    up = {"y": 1, "z": 2}[body.up_axis]
    centre = verts[body.faces].mean(1)[:, up]
    ids = torso.faces[((centre[torso.faces] * 25).floor() % 2 == 0)]
    ded.paint(Selection.from_ids(ids, body.num_faces), "#b8322a")
    donor.history.clear()
    donor.save(folder / "donor.gma")
    star = solid_shape("ring", (1.0, 0.85, 0.1), 96)
    star[..., :3] = np.where(star[..., 3:] > 0, star[..., :3], 0)
    iio.imwrite(folder / "stamp.png", (star * 255).astype(np.uint8))
    return folder / "avatar.gma", folder / "donor.gma", folder / "stamp.png"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out", nargs="?", default="docs/viewer_edit.gif")
    ap.add_argument("--size", type=int, default=360, help="square window size in pixels")
    ap.add_argument("--fine-per-face", type=int, default=2)
    ap.add_argument("--fps", type=float, default=8.0)
    args = ap.parse_args()
    xvfb = ensure_display("1024x768x24")
    try:
        with tempfile.TemporaryDirectory(prefix="gma-edit-demo-") as tmp:
            record(args, Path(tmp))
    finally:
        if xvfb is not None:
            xvfb.terminate()


class Driver:
    """The window's own callbacks, as a person's input calls them, with a screenshot per step."""

    def __init__(self, win):
        import glfw

        self.glfw, self.win = glfw, win
        self.frames: list = []

    def shot(self, count: int = 1) -> None:
        for _ in range(count):
            self.frames.append(self.win.screenshot()[..., :3].copy())

    def cursor(self, x, y) -> None:
        self.win._on_cursor(self.win.window, x, y)

    def press(self) -> None:
        self.win._on_button(self.win.window, self.glfw.MOUSE_BUTTON_LEFT, self.glfw.PRESS, 0)

    def release(self) -> None:
        self.win._on_button(self.win.window, self.glfw.MOUSE_BUTTON_LEFT, self.glfw.RELEASE, 0)

    def key(self, k) -> None:
        self.win._on_key(self.win.window, k, 0, self.glfw.PRESS, 0)
        self.win._on_key(self.win.window, k, 0, self.glfw.RELEASE, 0)

    def drag(self, start, points) -> None:
        """Press at ``start``, move through ``points`` with a screenshot after each, release."""
        self.cursor(*start)
        self.press()
        for x, y in points:
            self.cursor(x, y)
            self.shot()
        self.release()

    def settle(self) -> None:
        self.win.state.edit.wait()
        self.shot(3)


def record(args, tmp: Path) -> None:
    import imageio.v3 as iio
    import numpy as np
    import torch

    from gma.gpu import get_context
    from gma.view.source import avatar_source
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    torch.set_num_threads(1)
    avatar, donor, stamp = make_avatars(tmp, args.fine_per_face)
    ctx = get_context()
    state = ViewerState(ctx, avatar_source(ctx, avatar))
    state.orbit.zoom(4.0)  # closer: the upper body fills the frame
    win = ViewerWindow(state, args.size, args.size, panels=False)
    d = Driver(win)
    shirt = _shirt_on_screen(win)
    d.shot(4)
    _paint_stroke(d, shirt, args.size)
    _mirrored_stroke(d, shirt)
    _stamp(d, shirt, stamp, args.size)
    _transfer(d, shirt, donor)
    win.close()

    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    iio.imwrite(out, np.stack(d.frames), duration=1000 / args.fps, loop=0)
    print(f"wrote {out}: {len(d.frames)} frames, {out.stat().st_size / 1e6:.2f} MB; "
          f"history: {[r['op'] for r in state.source.avatar.history]}")


def _shirt_on_screen(win) -> tuple[float, float, float, float, float]:
    """Where the visible torso is: (centre x, centre y, top, bottom, half width) in pixels."""
    import numpy as np

    from gma.edit import Selection

    ed = win.state.edit
    view = ed.view(win.size)
    torso = Selection.from_regions(ed.body, "torso").mask().numpy()
    vis = np.nonzero(view.visible & torso)[0]
    cx, cy = np.median(view.px[vis], 0)
    top, bottom = np.percentile(view.px[vis][:, 1], [15, 85])
    half = np.percentile(np.abs(view.px[vis][:, 0] - cx), 70)
    return cx, cy, top, bottom, half


def _paint_stroke(d: Driver, shirt, n: int) -> None:
    """1. A red brush zig-zag across the shirt (P: paint tool)."""
    import numpy as np

    cx, _, top, bottom, half = shirt
    ed = d.win.state.edit
    d.key(d.glfw.KEY_P)
    ed.set_color("#d23c3c")
    ed.brush.radius = n / 28
    path = [(cx - half + 2 * half * (k % 2), top + (bottom - top) * 0.4 * k / 6) for k in range(7)]
    points = [(x0 + t * (x1 - x0), y0 + t * (y1 - y0))
              for (x0, y0), (x1, y1) in zip(path[:-1], path[1:]) for t in np.linspace(0, 1, 4)[1:]]
    d.drag(path[0], points)
    d.settle()


def _mirrored_stroke(d: Driver, shirt) -> None:
    """1b. X: mirror on, a green stroke down one side of the shirt lands on both sides; X again: off."""
    import numpy as np

    cx, _, top, bottom, half = shirt
    d.key(d.glfw.KEY_X)
    d.win.state.edit.set_color("#3cb44b")
    x = cx - 0.8 * half
    d.drag((x, top + 0.5 * (bottom - top)), [(x, top + (0.5 + 0.4 * t) * (bottom - top))
                                             for t in np.linspace(0, 1, 7)[1:]])
    d.key(d.glfw.KEY_X)
    d.settle()


def _stamp(d: Driver, shirt, stamp: Path, n: int) -> None:
    """2. Drop an image on the window, drag it to the chest's lower half, scale it up with the wheel, Enter."""
    import numpy as np

    cx, _, top, bottom, _ = shirt
    win = d.win
    win._on_drop(win.window, [str(stamp)])
    win.state.edit.stamp.size = n / 5
    d.shot(2)
    d.drag((n / 2, n / 2), [(n / 2 + t * (cx - n / 2), n / 2 + t * (top + 0.75 * (bottom - top) - n / 2))
                            for t in np.linspace(0, 1, 6)[1:]])
    for _ in range(3):
        win._on_scroll(win.window, 0, 1)  # wheel: bigger
        d.shot()
    d.key(d.glfw.KEY_ENTER)
    d.key(d.glfw.KEY_N)
    d.settle()


def _transfer(d: Driver, shirt, donor: Path) -> None:
    """3. Open the donor (drop a .gma), select the arms-and-shoulders area with a box, transfer tex."""
    import numpy as np

    cx, _, top, bottom, half = shirt
    win, ed = d.win, d.win.state.edit
    win._on_drop(win.window, [str(donor)])
    ed.transfer_what = "tex"
    d.shot(3)
    d.key(d.glfw.KEY_B)
    x0, y0, x1, y1 = cx - 1.6 * half, top - 0.1 * (bottom - top), cx + 1.6 * half, top + 0.35 * (bottom - top)
    d.drag((x0, y0), [(x0 + t * (x1 - x0), y0 + t * (y1 - y0)) for t in np.linspace(0, 1, 5)[1:]])
    d.shot(2)
    ed.transfer()
    ed.clear()
    d.settle()
    d.shot(4)


if __name__ == "__main__":
    main()
