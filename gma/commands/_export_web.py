"""``gma export avatar.gma page.html``: the avatar as one self-contained web page that plays it animated.

    gma export me.gma me.html                         # the walk, orbit/zoom, play/pause, time slider
    gma export me.gma me.html --motion walk --motion dance.npz --size 800x600   # a picker for the two
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gma.core.errors import InputError, MissingFileError
from gma.core.outputs import prepare_output_file

DEFAULT_MOTION = "walk"
# The page's starting view, as `gma render`'s: framing the motion, from the front, a little above.
ELEVATION = 10.0
# A page of more motions than this is a typo or a loop gone wrong; each adds ~0.4 MB per 4 seconds.
MAX_MOTIONS = 16


def _motion_name(spec: str) -> str:
    return Path(spec).stem if ("/" in spec or "." in spec) else spec


def run_web(args: argparse.Namespace) -> int:
    """Write the page; checks the output, the avatar, the motions and the build before the slow work."""
    out = Path(args.out)
    if args.format is not None:
        raise InputError(f"{out}: an .html export is a web page; --format {args.format} is for .ply/.glb/.obj")
    if args.frame is not None or args.every is not None:
        raise InputError(f"{out}: a web page plays whole motions; --frame and --every are for .ply/.glb/.obj")
    specs = args.motion or [DEFAULT_MOTION]
    if len(specs) > MAX_MOTIONS:
        raise InputError(f"{len(specs)} --motion options; a page holds at most {MAX_MOTIONS}")
    if not Path(args.avatar).is_file():
        raise MissingFileError(f"{args.avatar}: avatar file not found")
    prepare_output_file(out, args.force)

    from gma.avatar.avatar import Avatar
    from gma.body import load_body
    from gma.export import web
    from gma.view.controls import load_motion

    start = time.perf_counter()
    avatar = Avatar.load(args.avatar)
    body = load_body(avatar.body_name)
    if body.name != "anny":
        raise InputError(f"{args.avatar}: web pages play Anny avatars; this one is bound to {body.name!r}")
    motions = [(_motion_name(spec), load_motion(spec, body)) for spec in specs]
    for spec, (_, m) in zip(specs, motions):
        if len(m) == 0:
            raise InputError(f"motion {spec!r}: has no frames")
    bundle = web.page_bundle()
    _, camera = page_camera(avatar, body, motions[0][1])
    splats = web.skinned_splats(avatar, body)
    tracks = [(name, m, web.motion_bones(avatar, body, m)) for name, m in motions]
    page = web.page_html(Path(args.avatar).stem, splats, tracks, camera, bundle, args.size)
    web.write_page(out, page)
    print(f"wrote {out} ({len(splats.means):,} surfels, {len(tracks)} motion(s), {out.stat().st_size / 1e6:.1f} MB) "
          f"in {time.perf_counter() - start:.1f} s", file=sys.stderr)
    return 0


def page_camera(avatar, body, motion):
    """The page's starting view as an ``OrbitCamera`` and a ``PageCamera``: `gma render`'s framing of
    ``motion`` (its posed body's box, from the front, ``ELEVATION`` degrees above)."""
    from gma.export.web import PageCamera, motion_bounds
    from gma.view.orbit import OrbitCamera

    orbit = OrbitCamera.framing(*motion_bounds(avatar, body, motion), up_axis=body.up_axis)
    orbit.elevation = ELEVATION
    up = -orbit.camera(1, 1).viewmat[1, :3]  # OpenCV's image y points down
    camera = PageCamera(tuple(float(x) for x in orbit.eye), tuple(float(x) for x in orbit.target),
                        tuple(float(x) for x in up), float(orbit.fov_y))
    return orbit, camera
