"""Interactive editing in the viewer window (Xvfb is started when there is no DISPLAY):

1. paint of ~1,000 faces, from the mouse release (the "fill selection" button fires on release) to the
   updated frame presented, GPU work finished: goal <= 250 ms on lavapipe, <= 30 ms on a GPU;
2. a brush stroke dragged across the body through the window's mouse callbacks, one frame per cursor
   move (each frame applies the dabs queued since the last one): goal >= 5 updates per second on lavapipe.

Prints medians, the machine and its load, and where the time goes (paint solve + re-decode in
gma.edit, row upload, frame). The avatar is a fresh one (``Avatar.create``), the size of a fitted one.

    python benchmarks/viewer_edit.py --size 640x480 --fine-per-face 4 --repeats 5 [--mirror]
"""

from __future__ import annotations

import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from benchmarks.common import machine  # noqa: E402
from viewer.display import ensure_display  # noqa: E402


def wait_gpu(ctx, probe) -> None:
    """Block until the queue has finished everything submitted (a 4-byte readback)."""
    import numpy as np

    ctx.read(probe, np.uint32, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--size", default="640x480", help="window size WxH")
    ap.add_argument("--fine-per-face", type=int, default=4)
    ap.add_argument("--feature-dim", type=int, default=32)
    ap.add_argument("--faces", type=int, default=1000, help="faces painted by the fill")
    ap.add_argument("--radius", type=float, default=20.0, help="brush radius in pixels")
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--stroke-frames", type=int, default=30)
    ap.add_argument("--motion", default=None, help="play this motion while painting (e.g. walk)")
    ap.add_argument("--mirror", action="store_true", help="paint the strokes with the mirror toggle on (X): "
                                                          "each dab lands on both sides")
    args = ap.parse_args()
    xvfb = ensure_display()
    try:
        with tempfile.TemporaryDirectory(prefix="gma-bench-edit-") as tmp:
            run(args, Path(tmp))
    finally:
        if xvfb is not None:
            xvfb.terminate()


COLORS = ["#c03030", "#3050c0", "#20a040", "#f0f0f0", "#101010", "#d0a020"]


def run(args, tmp: Path) -> None:
    import torch

    from gma.core.args import parse_image_size

    torch.set_num_threads(1)  # as the viewer does (viewer/app.py)
    size = parse_image_size(args.size)
    bench = _open_window(args, tmp, size)
    win, ed = bench["win"], bench["win"].state.edit
    cand, centre = _select_chest_faces(ed, size, args.faces)
    ed.background = False  # warm-up, synchronous (first solve allocates)
    ed.set_color(COLORS[-1])
    ed.fill()
    win.draw_frame()
    wait_gpu(bench["ctx"], bench["probe"])
    sync = _time_fill_synchronous(bench, args.repeats)
    background = _time_fill_background(bench, args.repeats)
    _print_fill(bench, args, sync, background)
    _time_strokes(bench, args, ed.view(size).px[cand], centre, size)
    win.close()


def _open_window(args, tmp: Path, size) -> dict:
    """A fresh avatar in a viewer window without panels, its row uploads timed: a dict of ctx, body, win,
    size, probe (a buffer to wait for the GPU with) and upload_ms (the uploads' times, appended per call)."""
    from gma.avatar import Avatar
    from gma.avatar.config import AvatarConfig
    from gma.body import load_body
    from gma.gpu import get_context
    from gma.view.source import avatar_source
    from viewer.state import ViewerState
    from viewer.window import ViewerWindow

    ctx = get_context()
    body = load_body("anny")
    path = tmp / "avatar.gma"
    Avatar.create(AvatarConfig(feature_dim=args.feature_dim, fine_per_face=args.fine_per_face), body).save(path)
    state = ViewerState(ctx, avatar_source(ctx, path))
    if args.motion:
        state.play_motion(args.motion)
    win = ViewerWindow(state, *size, panels=False)
    bench = {"ctx": ctx, "body": body, "win": win, "size": size, "probe": ctx.buffer(4, "bench.probe"),
             "upload_ms": []}
    real_update = state.source.update_rows

    def timed_update(*a, **k):  # where the time goes: the row upload inside each edit
        t0 = time.perf_counter()
        out = real_update(*a, **k)
        bench["upload_ms"].append((time.perf_counter() - t0) * 1e3)
        return out

    state.source.update_rows = timed_update
    for _ in range(5):
        win.draw_frame()
    wait_gpu(ctx, bench["probe"])
    return bench


def _select_chest_faces(ed, size, faces: int):
    """Select the ``faces`` visible torso faces nearest the chest's screen position: (the visible torso
    faces, the chest's pixel position)."""
    import numpy as np

    from gma.edit import Selection

    view = ed.view(size)
    vis = np.nonzero(view.visible)[0]
    torso = Selection.from_regions(ed.body, "torso").mask().numpy()
    cand = vis[torso[vis]]
    centre = np.median(view.px[cand], 0)
    order = cand[np.argsort(np.linalg.norm(view.px[cand] - centre, axis=1))]
    ed.set_selection(Selection.from_ids(order[:faces], ed.body.num_faces))
    return cand, centre


def _time_fill_synchronous(bench, repeats: int) -> dict:
    """The solve, the row upload and the frame one after the other (gma.edit's time), in ms per repeat."""
    win, ctx, upload_ms = bench["win"], bench["ctx"], bench["upload_ms"]
    ed = win.state.edit
    out = {"total": [], "solve": [], "upload": [], "frame": []}
    for i in range(repeats):
        ed.set_color(COLORS[i % len(COLORS)])
        upload_ms.clear()
        t0 = time.perf_counter()
        out["change"] = ed.fill()
        t1 = time.perf_counter()
        win.draw_frame()
        wait_gpu(ctx, bench["probe"])
        t2 = time.perf_counter()
        out["total"].append((t2 - t0) * 1e3)
        out["upload"].append(sum(upload_ms))
        out["solve"].append((t1 - t0) * 1e3 - out["upload"][-1])
        out["frame"].append((t2 - t1) * 1e3)
    return out


def _time_fill_background(bench, repeats: int) -> dict:
    """As the window does it: preview at once, solve on the worker, frames go on until it lands."""
    win, ctx = bench["win"], bench["ctx"]
    ed = win.state.edit
    ed.background = True
    out = {"first": [], "exact": [], "frames": []}
    for i in range(repeats):
        ed.set_color(COLORS[(i + 3) % len(COLORS)])
        t0 = time.perf_counter()
        ed.fill()  # what the button's release calls: returns at once
        win.draw_frame()
        wait_gpu(ctx, bench["probe"])
        out["first"].append((time.perf_counter() - t0) * 1e3)
        n = 1
        while ed.busy:
            win.draw_frame()  # polls: uploads the solved rows when the worker is done
            n += 1
        win.draw_frame()
        wait_gpu(ctx, bench["probe"])
        out["exact"].append((time.perf_counter() - t0) * 1e3)
        out["frames"].append(n)
    return out


def _print_fill(bench, args, sync: dict, background: dict) -> None:
    import torch

    med = statistics.median
    src, change = bench["win"].state.source, sync["change"]
    w, h = bench["size"]
    print(f"device: {bench['ctx'].name}")
    print(f"machine: {machine()}; torch threads {torch.get_num_threads()}")
    print(f"avatar: {bench['body'].num_faces} faces x {args.fine_per_face} surfels = {len(src.decoded.colors)} "
          f"surfels, feature_dim {args.feature_dim}; window {w}x{h}"
          + (f", motion {args.motion} playing" if args.motion else ""))
    print(f"1. paint of {len(change.faces)} faces, mouse release -> frame presented (GPU done), median of "
          f"{args.repeats} (goal <= 250 ms on lavapipe):")
    print(f"   window (background solve): painted colour on screen {med(background['first']):.0f} ms; solved "
          f"features on screen {med(background['exact']):.0f} ms, {med(background['frames']):.0f} frames drawn "
          "meanwhile")
    print(f"   synchronous: {med(sync['total']):.0f} ms = solve + re-decode (gma.edit) {med(sync['solve']):.0f} ms "
          f"({change.info.get('iterations', '?')} iterations) + row upload ({len(change.rows)} rows) "
          f"{med(sync['upload']):.1f} ms + frame draw/present/GPU wait {med(sync['frame']):.0f} ms")
    print(f"   samples sync: {', '.join(f'{t:.0f}' for t in sync['total'])}; preview: "
          f"{', '.join(f'{t:.0f}' for t in background['first'])}; solved: "
          f"{', '.join(f'{t:.0f}' for t in background['exact'])} ms")


def _time_strokes(bench, args, torso_px, centre, size) -> None:
    """Brush strokes through the mouse callbacks, one frame per move, down the torso in a wave."""
    import numpy as np

    win = bench["win"]
    ed = win.state.edit
    ed.clear()
    ed.brush.radius = args.radius
    ed.mirror = args.mirror
    win.tool = "paint"
    y0, y1 = np.percentile(torso_px[:, 1], 10), np.percentile(torso_px[:, 1], 90)
    rates, solves, lands = [], [], []
    for rep in range(max(1, args.repeats // 2)):
        ed.set_color(COLORS[rep % len(COLORS)])
        n = args.stroke_frames
        pts = [(centre[0] + 0.3 * (y1 - y0) * np.sin(k / n * 2 * np.pi), y0 + (y1 - y0) * k / n) for k in range(n)]
        el, tail = _drag_stroke(bench, pts, size)
        st = ed.last_stroke
        rates.append((n - 1) / el)
        solves.append(st.updates / (el + tail))
        lands.append(tail * 1e3)
        print(f"   stroke {rep}: {n - 1} frames in {el:.2f} s = {rates[-1]:.1f} FPS with the brush shown; "
              f"{st.updates} solves ({st.dabs} dabs, {st.faces} faces); after release {tail * 1e3:.0f} ms "
              f"until solved and folded into one record ({len(win.state.source.avatar.history)} records)")
    med = statistics.median
    mirrored = ", mirrored" if args.mirror else ""
    print(f"2. brush stroke (radius {args.radius:g} px{mirrored}) while dragging: median {med(rates):.1f} frames/s, "
          f"each showing the dabs so far (goal >= 5 on lavapipe); solved updates {med(solves):.1f}/s; "
          f"release -> stroke solved {med(lands):.0f} ms")


def _drag_stroke(bench, pts, size) -> tuple[float, float]:
    """Press, move through ``pts`` (pixels) drawing a frame per move, release: (seconds while dragging,
    seconds from the release until the stroke is solved and folded)."""
    import glfw

    win, ctx = bench["win"], bench["ctx"]
    ww, wh = glfw.get_window_size(win.window)
    sx, sy = ww / size[0], wh / size[1]  # callbacks take window coordinates
    win._on_cursor(win.window, pts[0][0] * sx, pts[0][1] * sy)
    win._on_button(win.window, glfw.MOUSE_BUTTON_LEFT, glfw.PRESS, 0)
    t0 = time.perf_counter()
    for x, y in pts[1:]:
        win._on_cursor(win.window, x * sx, y * sy)
        win.draw_frame()  # applies the queued dabs: preview now, solve when the worker is free
    wait_gpu(ctx, bench["probe"])
    el = time.perf_counter() - t0
    win._on_button(win.window, glfw.MOUSE_BUTTON_LEFT, glfw.RELEASE, 0)
    t1 = time.perf_counter()
    while win.state.edit.stroke is not None:
        win.draw_frame()
    wait_gpu(ctx, bench["probe"])
    return el, time.perf_counter() - t1


if __name__ == "__main__":
    main()
