"""``gma export avatar.gma OUT``: the avatar posed, as a Gaussian-splat PLY or a mesh other tools read.

    gma export me.gma me.ply                              # 3DGS splat file, canonical pose
    gma export me.gma me_2dgs.ply --format 2dgs --pose tpose
    gma export me.gma me.glb --texture 1024               # posed morphed mesh, UVs + baked texture
    gma export me.gma walk.ply --motion walk.bvh --every 10   # walk_00000.ply, walk_00010.ply, ...
    gma export me.gma me.html --motion walk --motion turn      # a web page that plays the avatar
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gma.core.args import non_negative_int, parse_image_size, positive_float, positive_int
from gma.core.errors import InputError, MissingFileError
from gma.core.outputs import prepare_output_file

SUFFIXES = (".ply", ".glb", ".obj", ".html")
FORMATS = ("3dgs", "2dgs", "mesh")


def register(subparsers) -> None:
    p = subparsers.add_parser("export", help="export an avatar as a Gaussian-splat PLY, a mesh (GLB/OBJ/PLY) or a "
                              "web page that plays it (HTML)",
                              description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("avatar", help="fitted avatar .gma")
    p.add_argument("out", help="output .ply (splats, or a mesh with --format mesh), .glb or .obj (mesh), .html "
                   "(a self-contained page that plays the avatar)")
    p.add_argument("--format", choices=FORMATS, default=None,
                   help="3dgs: INRIA splat layout, three scales (default for .ply); 2dgs: two scales; mesh: the "
                        "morphed body mesh (default for .glb/.obj)")
    p.add_argument("--sh-degree", type=int, choices=(0, 3), default=0,
                   help="spherical-harmonic degree of the splat colours (3 adds zero rest coefficients)")
    p.add_argument("--thickness", type=positive_float, default=1e-4,
                   help="3dgs: size of each surfel's flat axis in metres (default 1e-4)")
    p.add_argument("--pose", default="canonical", choices=("canonical", "tpose", "apose"),
                   help="named pose when neither --motion nor --frame is given")
    p.add_argument("--motion", action="append", default=None,
                   help="motion file (.bvh, AMASS/SMPL-X .npz, an Anny motion or sequence body.npz); .html: also a "
                        "built-in motion (walk, turn, wave), repeatable for a picker (default walk)")
    p.add_argument("--frame", type=non_negative_int, default=None,
                   help="this frame of --motion (or of the avatar's fitted sequence)")
    p.add_argument("--every", type=positive_int, default=None,
                   help="every K-th frame of --motion, as OUT_NNNNN.ext (--motion without --frame: every frame)")
    p.add_argument("--texture", type=non_negative_int, default=0,
                   help="mesh: bake the colours into an N×N texture on the body's UVs (0: vertex colours)")
    p.add_argument("--size", type=parse_image_size, default=None,
                   help=".html: the view's size in pixels, N or WxH (default: the browser window)")
    p.add_argument("--force", action="store_true", help="overwrite existing outputs")
    p.set_defaults(func=run)


def _outputs(out: Path, labels: list[str | None]) -> list[Path]:
    return [out if label is None else out.with_name(f"{out.stem}_{label}{out.suffix}") for label in labels]


def run(args: argparse.Namespace) -> int:
    out = Path(args.out)
    suffix = out.suffix.lower()
    if suffix not in SUFFIXES:
        raise InputError(f"{out}: unknown export format {out.suffix!r}; expected {', '.join(SUFFIXES)}")
    if suffix == ".html":
        from gma.commands._export_web import run_web

        return run_web(args)
    if args.size is not None:
        raise InputError(f"--size is for .html pages; {out} is not one")
    if args.motion is not None and len(args.motion) > 1:
        raise InputError(f"{out}: give one --motion (several are for .html pages)")
    args.motion = args.motion[0] if args.motion else None
    fmt = args.format or ("3dgs" if suffix == ".ply" else "mesh")
    if fmt != "mesh" and suffix != ".ply":
        raise InputError(f"{out}: --format {fmt} writes a splat .ply")
    if args.texture and fmt != "mesh":
        raise InputError(f"--texture is for mesh exports; {out} is a {fmt} splat file")
    if args.texture > 8192:
        raise InputError(f"--texture {args.texture}: at most 8192")
    if args.every is not None and args.motion is None:
        raise InputError("--every needs --motion FILE")
    if not Path(args.avatar).is_file():
        raise MissingFileError(f"{args.avatar}: avatar file not found")
    series = args.every is not None or (args.motion is not None and args.frame is None)
    if not series:  # a single output: check it before loading anything
        prepare_output_file(out, args.force)

    from gma.avatar.avatar import Avatar
    from gma.body import load_body
    from gma.export import export_poses, posed_mesh, posed_splats, write_mesh, write_splats
    from gma.export.mesh import surfel_vertex_colors

    start = time.perf_counter()
    avatar = Avatar.load(args.avatar)
    body = load_body(avatar.body_name)
    poses = export_poses(avatar, body, args.pose, args.motion, args.frame, args.every, args.avatar)
    paths = _outputs(out, [p.label for p in poses])
    if series:
        for path in paths:
            prepare_output_file(path, args.force)
    decoded = avatar.decode()
    faces = body.faces.numpy()
    colors = surfel_vertex_colors(decoded, faces, body.num_vertices) if fmt == "mesh" else None
    total = 0
    for pose, path in zip(poses, paths):
        splats = posed_splats(avatar, body, pose.params, decoded)
        if fmt == "mesh":
            mesh = posed_mesh(splats["vertices"], faces, colors, body.face_uvs.numpy(), args.texture)
            write_mesh(path, mesh)
        else:
            write_splats(path, splats, fmt, args.sh_degree, args.thickness)
        total += path.stat().st_size
    what = (f"{len(decoded.binding):,} surfels" if fmt != "mesh" else f"mesh of {body.num_vertices:,} vertices")
    where = paths[0] if len(paths) == 1 else f"{len(paths)} files {paths[0]} .. {paths[-1].name}"
    print(f"wrote {where} ({fmt}, {what}, {total / 1e6:.1f} MB) in {time.perf_counter() - start:.1f} s",
          file=sys.stderr)
    return 0
