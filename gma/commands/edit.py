"""``gma edit IN.gma -o OUT.gma``: scriptable edits of a fitted avatar (the library is ``gma.edit``).

    gma edit in.gma -o out.gma --select region:torso --paint "#c03030"
    gma edit in.gma -o out.gma --select selection.json --stamp logo.png --view front --size 0.15m
    gma edit in.gma -o out.gma --select wand:front@320,240 --transfer donor.gma --what tex
    gma edit in.gma -o out.gma --select brush:left@200,180,30 --mirror --paint red   # both sides
    gma edit in.gma -o out.gma --shape 0.5,0.5,0.5,0.5,0.7,0.5
    gma edit in.gma --history            # list records
    gma edit in.gma -o out.gma --undo 2  # drop the last two records, restoring exactly

Selections (``--select``, repeatable, united; ``--deselect`` removes): ``region:NAME[,NAME...]`` (torso,
arms, legs, head, hands, feet, upper_body, lower_body or a part label), a selection ``.json`` file,
``all``, ``unseen`` (the faces the fit's frames never showed, whose look was filled in), and screen-space
specs in a named view of the canonical pose (``--view-size`` pixels):
``wand:VIEW@X,Y`` (``--wand-tolerance``), ``box:VIEW@X0,Y0,X1,Y1``, ``brush:VIEW@X,Y,R``.
Every bad input is one line naming the problem, exit code 2, and nothing is written.
"""

from __future__ import annotations

import argparse
from pathlib import Path


def register(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("edit", help="paint, stamp, transfer features, set shape, undo (a .gma avatar)",
                       description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("avatar", help="the .gma avatar to edit")
    p.add_argument("-o", "--out", help="where to write the edited avatar (atomically)")
    p.add_argument("--force", action="store_true",
                   help="replace an existing -o file (the input file too, when -o names it)")
    # The name this option had before every command said --force; kept so that old scripts still run.
    p.add_argument("--overwrite", dest="force", action="store_true", help=argparse.SUPPRESS)
    p.add_argument("--select", action="append", default=[], metavar="SPEC", help="faces to edit (see above)")
    p.add_argument("--deselect", action="append", default=[], metavar="SPEC", help="faces to leave out")
    p.add_argument("--grow", type=int, default=0, help="grow the selection by N rings of faces")
    p.add_argument("--shrink", type=int, default=0, help="shrink the selection by N rings of faces")
    p.add_argument("--mirror", action="store_true",
                   help="also edit the mirror image of the selection across the body's left-right plane "
                        "(paint and transfer; a stamp is placed from one view)")
    p.add_argument("--wand-tolerance", type=float, default=0.1, help="magic wand colour distance (RGB, 0..1.7)")
    p.add_argument("--view-size", type=int, default=512, help="pixels of the named views (wand/box/brush/stamp)")
    op = p.add_mutually_exclusive_group()
    op.add_argument("--paint", metavar="COLOUR", help="paint colour: #rrggbb, r,g,b in [0, 1], or a name")
    op.add_argument("--stamp", metavar="IMAGE", help="stamp an image (PNG with alpha) or shape:circle|square|ring")
    op.add_argument("--transfer", metavar="DONOR", help="copy features of the selected faces from a donor .gma")
    op.add_argument("--undo", type=int, metavar="N", help="undo the last N history records")
    op.add_argument("--revert", type=int, metavar="I", help="undo every record after the first I")
    op.add_argument("--history", action="store_true", help="list the avatar's edit records")
    p.add_argument("--what", default="tex", choices=("tex", "geo", "both"), help="transfer: which features")
    p.add_argument("--view", default="front", help="stamp: front|back|left|right (canonical pose)")
    p.add_argument("--camera", help="stamp: a camera JSON file ({width, height, K, w2c}) instead of --view")
    p.add_argument("--size", default="0.15m", help="stamp: image size, e.g. 0.15m, 15cm or 120px")
    p.add_argument("--at", help="stamp: centre pixel X,Y in the view (default: centre of the selection)")
    p.add_argument("--rotation", type=float, default=0.0, help="stamp: rotation in degrees")
    p.add_argument("--color", default="#ffffff", help="stamp: colour of a shape:... stamp")
    p.add_argument("--shape", help="set the body shape: comma-separated values (Anny: 6 phenotype values)")
    p.add_argument("--expression", help="set the default expression: comma-separated values")
    p.set_defaults(func=run)


def _floats(text: str, what: str) -> list[float]:
    from gma.edit import EditError

    try:
        return [float(v) for v in text.split(",")]
    except ValueError:
        raise EditError(f"{what} must be comma-separated numbers, got {text!r}") from None


def _screen(ed, spec: str, size: int):
    """(view, numbers) of a ``KIND:VIEW@a,b,...`` spec."""
    from gma.edit import EditError

    kind, _, rest = spec.partition(":")
    view_name, at, nums = rest.partition("@")
    if not at:
        raise EditError(f"selection {spec!r}: expected {kind}:VIEW@numbers, e.g. {kind}:front@320,240")
    return ed.named_view(view_name, size, size), _floats(nums, f"selection {spec!r}")


def parse_selection(ed, spec: str, args):
    """One ``--select`` spec -> Selection."""
    from gma.edit import EditError, Selection

    body = ed.body
    if spec == "all":
        return Selection.everything(ed.num_faces)
    if spec == "unseen":
        return Selection.unseen(ed.avatar)
    if spec.startswith("region:"):
        names = [n for n in spec[len("region:"):].split(",") if n]
        if not names:
            raise EditError(f"selection {spec!r} names no region")
        return Selection.from_regions(body, *names)
    kind = spec.split(":", 1)[0]
    if kind in ("wand", "box", "brush"):
        view, nums = _screen(ed, spec, args.view_size)
        need = {"wand": 2, "box": 4, "brush": 3}[kind]
        if len(nums) != need:
            raise EditError(f"selection {spec!r}: {kind} takes {need} numbers after @")
        if kind == "wand":
            return ed.wand(view, nums[0], nums[1], args.wand_tolerance)
        if kind == "box":
            return Selection.box(view, nums)
        return Selection.brush(view, nums[:2], nums[2])
    path = Path(spec)
    if path.suffix.lower() == ".json" or path.exists():
        try:
            return Selection.load(path, body.name, ed.num_faces)
        except (ValueError, FileNotFoundError) as exc:
            raise EditError(str(exc)) from None
    raise EditError(f"cannot read selection {spec!r}: use region:NAME, a .json file, all, unseen, wand:VIEW@X,Y, "
                    "box:VIEW@X0,Y0,X1,Y1 or brush:VIEW@X,Y,R")


def _selection(ed, args):
    from gma.edit import EditError

    sel = None
    for spec in args.select:
        s = parse_selection(ed, spec, args)
        sel = s if sel is None else sel.union(s)
    if sel is None:
        return None
    for spec in args.deselect:
        sel = sel.subtract(parse_selection(ed, spec, args))
    if args.grow:
        sel = sel.grow(ed.graph, args.grow)
    if args.shrink:
        sel = sel.shrink(ed.graph, args.shrink)
    if args.mirror:
        sel = sel.symmetric(ed.mirror_map)
    if len(sel) == 0:
        raise EditError(f"the selection {' + '.join(args.select)} is empty: no faces selected")
    return sel


def _stamp(ed, sel, args):
    from gma.edit import EditError, StampPlacement, load_stamp_image, parse_color, solid_shape
    if args.stamp.startswith("shape:"):
        image = solid_shape(args.stamp[len("shape:"):], parse_color(args.color))
    else:
        image = load_stamp_image(args.stamp)
    if args.camera:
        from gma.core.camera import Camera

        cam = Camera.load(args.camera)
        view = ed.screen_view(cam)
        if not view.visible.any():
            raise EditError(f"camera {args.camera} sees no face of the avatar")
    else:
        view = ed.named_view(args.view, args.view_size, args.view_size)
    size, unit = StampPlacement.parse_size(args.size, "--size")
    centre = None
    if args.at:
        centre = _floats(args.at, "--at")
        if len(centre) != 2:
            raise EditError(f"--at must be X,Y, got {args.at!r}")
    placement = StampPlacement(centre, size, unit, args.rotation)
    return ed.stamp(image, view, placement, sel, name=Path(args.stamp).name)


def _check_numbers(args) -> None:
    """The numeric options against the ranges of :mod:`gma.edit.limits`, before any file is read (each
    error names the option and its range). --shape / --expression need the body's ranges: see run."""
    from gma.edit import StampPlacement
    from gma.edit.limits import MAX_COLOR_TOLERANCE, MAX_RINGS, MAX_ROTATION_DEG, VIEW_SIZE, check_number, check_pixel

    check_number("--wand-tolerance", args.wand_tolerance, 0.0, MAX_COLOR_TOLERANCE)
    check_number("--view-size", args.view_size, *VIEW_SIZE, "px")
    check_number("--grow", args.grow, 0, MAX_RINGS, "rings")
    check_number("--shrink", args.shrink, 0, MAX_RINGS, "rings")
    check_number("--rotation", args.rotation, -MAX_ROTATION_DEG, MAX_ROTATION_DEG, "degrees")
    StampPlacement.parse_size(args.size, "--size")
    if args.at:
        check_pixel("--at", _floats(args.at, "--at"))


def run(args: argparse.Namespace) -> int:
    # Bad input raises EditError (a GmaError): gma.cli prints it as one line and exits with 2.
    from gma.avatar import Avatar
    from gma.core.outputs import prepare_output_file
    from gma.edit import EditError, Editor, summarize

    src = Path(args.avatar)
    edits = any(v is not None for v in (args.paint, args.stamp, args.transfer, args.undo, args.revert, args.shape,
                                        args.expression))
    if not edits and not args.history:
        raise EditError("nothing to do: give --paint, --stamp, --transfer, --shape, --expression, --undo, "
                        "--revert or --history")
    if edits and not args.out:
        raise EditError("-o/--out is required to write the edited avatar")
    if args.out and Path(args.out).suffix.lower() != ".gma":
        raise EditError(f"-o {args.out}: the output must be a .gma file")
    if edits and Path(args.out).resolve() == src.resolve() and not args.force:
        raise EditError(f"-o {args.out} is the input file; pass --force to replace it")
    if edits:
        prepare_output_file(args.out, args.force, "edited avatar")
    if args.mirror and (args.paint is None and args.transfer is None):
        raise EditError("--mirror applies to --paint and --transfer (a stamp is placed from one view: stamp "
                        "each side from its own view)")
    _check_numbers(args)
    shape = None if args.shape is None else _floats(args.shape, "--shape")
    expression = None if args.expression is None else _floats(args.expression, "--expression")
    avatar = Avatar.load(src)
    if args.history:
        if not avatar.history:
            print(f"{src}: no edit records")
        for i, rec in enumerate(avatar.history):
            print(f"{i + 1:3d}  {summarize(rec)}")
        if not edits:
            return 0
    ed = Editor(avatar)
    ed.check_body(shape, expression)  # before any solve: a bad value must not cost a paint first
    if args.undo is not None:
        if not 0 < args.undo <= len(avatar.history):
            raise EditError(f"--undo {args.undo}: the history of {src} holds {len(avatar.history)} records")
        for _ in range(args.undo):
            ed.undo()
    elif args.revert is not None:
        ed.revert(args.revert)
    needs_sel = args.paint is not None or args.transfer is not None
    sel = _selection(ed, args) if (args.select or needs_sel) else None
    if needs_sel and sel is None:
        raise EditError("--paint and --transfer need --select")
    if args.paint is not None:
        ch = ed.paint(sel, args.paint)
        print(f"painted {len(ch.faces)} faces ({ch.info['iterations']} solver steps)")
    elif args.stamp is not None:
        ch = _stamp(ed, sel, args)
        print(f"stamped {len(ch.faces)} faces")
    elif args.transfer is not None:
        donor = Avatar.load(args.transfer)
        ch = ed.transfer(donor, sel, args.what, donor_name=str(args.transfer), target_name=str(src))
        print(f"transferred {args.what} of {len(ch.faces)} faces from {args.transfer} ({ch.info['mode']})")
    if shape is not None or expression is not None:
        ed.set_body(shape, expression)
    out = avatar.save(args.out)
    print(f"wrote {out} ({len(avatar.history)} history records)")
    return 0
