"""``gma body``: inspect the body model and export posed meshes.

    gma body info [--model anny|smplx] [--smplx-dir DIR]
    gma body export-obj OUT.obj [--motion walk --frame 10] [--model ...]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from gma.core.args import non_negative_int, positive_int
from gma.core.atomic import atomic_write_bytes
from gma.core.errors import InputError
from gma.core.outputs import prepare_output_file


def register(subparsers) -> None:
    p = subparsers.add_parser("body", help="inspect the body model, export posed meshes")
    sub = p.add_subparsers(dest="body_command", metavar="ACTION", required=True)

    def common(sp):
        sp.add_argument("--model", default="anny", choices=("anny", "smplx"), help="body model")
        sp.add_argument("--smplx-dir", default=None, help="folder with SMPLX_*.npz (default $GMA_SMPLX_DIR)")
        sp.add_argument("--gender", default="neutral", help="SMPL-X gender (neutral, male, female)")

    info = sub.add_parser("info", help="sizes, parameter spaces and regions of the body")
    common(info)
    info.set_defaults(func=run_info)

    exp = sub.add_parser("export-obj", help="write the posed body as a Wavefront OBJ (with UVs)")
    common(exp)
    exp.add_argument("out", type=Path, help="output .obj path")
    exp.add_argument("--motion", default=None, help="built-in motion (Anny): turn, walk, wave, expressions")
    exp.add_argument("--frame", type=non_negative_int, default=0, help="frame of the motion")
    exp.add_argument("--frames", type=positive_int, default=120, help="length of the motion")
    exp.add_argument("--force", action="store_true", help="overwrite an existing OBJ")
    exp.set_defaults(func=run_export)


def _body(args: argparse.Namespace):
    from gma.body import load_body

    if args.model == "smplx":
        return load_body("smplx", smplx_dir=args.smplx_dir, gender=args.gender)
    return load_body("anny")


def run_info(args: argparse.Namespace) -> int:
    body = _body(args)
    print(body)
    print(f"skinning: {body.skin_indices.shape[1]} influences per vertex; up axis {body.up_axis}")
    for space in body.param_spaces.values():
        rng = "" if space.low is None else f" in [{space.low.min():g}, {space.high.max():g}]"
        shown = ", ".join(space.labels[:6]) + (" ..." if space.size > 6 else "")
        print(f"  {space.name}: {space.size} x {list(space.entry_shape) or 'scalar'}{rng} ({shown})")
    print("regions: " + ", ".join(f"{k} {int(v.sum())}" for k, v in body.regions.items()))
    print("face labels: " + ", ".join(body.face_label_names))
    return 0


def write_obj(path: Path, vertices: np.ndarray, faces: np.ndarray, face_uvs: np.ndarray | None = None
              ) -> None:
    """Vertices [V, 3], faces [F, 3] and optional per-corner UVs [F, 3, 2] as OBJ (1-based indices)."""
    lines = ["# written by gma body export-obj"]
    lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    if face_uvs is not None:
        lines += [f"vt {u:.6f} {v:.6f}" for u, v in face_uvs.reshape(-1, 2)]
        corner = np.arange(len(faces) * 3).reshape(-1, 3) + 1
        pairs = zip(faces, corner, strict=True)
        lines += [f"f {a + 1}/{ta} {b + 1}/{tb} {c + 1}/{tc}" for (a, b, c), (ta, tb, tc) in pairs]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_bytes(path, ("\n".join(lines) + "\n").encode())


def run_export(args: argparse.Namespace) -> int:
    import torch

    prepare_output_file(args.out, args.force, "OBJ file")
    if args.frame >= args.frames:
        raise InputError(f"--frame {args.frame} is past the motion's last frame ({args.frames - 1})")
    body = _body(args)
    if args.motion:
        from gma.body.motions import motion

        params = motion(args.motion, args.frames, body).params(args.frame)
    else:
        params = body.canonical_params()
    with torch.no_grad():
        verts = body.pose(params).vertices.numpy()
    uvs = body.face_uvs.numpy() if bool(body.face_uvs.abs().sum() > 0) else None
    write_obj(args.out, verts, body.faces.numpy(), uvs)
    print(f"wrote {args.out} ({body.num_vertices} vertices, {body.num_faces} faces)")
    return 0
