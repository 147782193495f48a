"""Before/after pictures of each edit for ``docs/editing.md`` (written by this script, not by hand):
a painted sleeve, a logo stamped on the chest, trousers texture and loose-sleeve geometry transferred
from a second person of another body shape with the same decoders.

The avatars are the tests' pseudo-fitted ones (``tests/edit_helpers.py``: texture decoders and features
fitted to a speckled garment pattern) at the default size, since ``gma demo`` does not write an avatar
this script could rely on quickly; pass ``--avatar`` to use a fitted ``.gma`` instead.

    python benchmarks/edit_pictures.py [--avatar demo/avatar.gma] [--out docs]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--avatar", help="a fitted .gma (default: a pseudo-fitted avatar)")
    ap.add_argument("--out", default=str(REPO / "docs"))
    ap.add_argument("--size", type=int, default=256)
    args = ap.parse_args()
    import numpy as np
    import torch
    from edit_helpers import fitted_avatar

    from gma.avatar import Avatar
    from gma.avatar.gpu import AvatarRenderer
    from gma.body import load_body
    from gma.edit import Editor, Selection, StampPlacement
    from gma.gpu import get_context
    from gma.render.image_io import save_png

    ctx = get_context()
    body = load_body("anny")
    av = Avatar.load(args.avatar, body) if args.avatar else fitted_avatar(body, feature_dim=32, fine_per_face=4,
                                                                         hidden=128)
    out = Path(args.out)
    ed = Editor(av, body, ctx)
    front = ed.named_view("front", args.size, args.size)
    left = ed.named_view("left", args.size, args.size)
    renderer = AvatarRenderer(ctx, av, body, decoded=ed.decoded)

    def shot(view):
        return renderer.render(ed.params(), view.camera, (1.0, 1.0, 1.0))

    def pair(name, view, change_fn):
        before = shot(view)
        ch = change_fn()
        renderer.update_rows(ch.rows, ch.mesh)
        after = shot(view)
        save_png(out / f"edit_{name}.png", np.concatenate([before, after], 1))
        print(f"wrote {out / f'edit_{name}.png'} ({len(ch.faces)} faces, {ch.info})")

    # A painted sleeve: the avatar's left arm, red.
    arm = Selection.from_regions(body, "arms")
    left_side = torch.from_numpy(front.vertices[body.faces.numpy()].mean(1)[:, 0] > 0)
    sleeve = Selection.from_mask(arm.mask() & left_side)
    pair("paint_sleeve", front, lambda: ed.paint(sleeve, "#c03030"))

    # A logo on the chest: a yellow ring around a blue disc, 0.18 m wide.
    r = 128
    yy, xx = (np.mgrid[0:r, 0:r] + 0.5) / r * 2 - 1
    rad = np.hypot(xx, yy)
    logo = np.zeros((r, r, 4), np.float32)
    logo[..., :3] = np.where((rad > 0.65)[..., None], [1.0, 0.85, 0.1], [0.1, 0.2, 0.8])
    logo[..., 3] = np.clip((1 - rad) * r / 2, 0, 1)
    torso = body.region_mask("torso").numpy() & front.visible
    chest = front.px[torso].mean(0) - np.array([0, 0.06 * args.size])
    pair("stamp_logo", front, lambda: ed.stamp(logo, front, StampPlacement(tuple(chest), 0.18, "m")))

    # A second person: another body shape, the same decoders, other features. Their trousers are a
    # striped denim (painted per surfel), their sleeves loose (f_geo fitted to push the mesh layer out).
    donor = Avatar.create(av.config, body, torch.tensor((0.9, 0.3, 0.8, 0.9, 0.95, 0.4)))
    donor.model.load_state_dict(av.model.state_dict())
    ded = Editor(donor, body, ctx)
    legs = Selection.from_regions(body, "legs")
    nk = av.config.fine_per_face
    height = torch.from_numpy(front.vertices[body.faces.numpy()].mean(1)[:, 2])[legs.faces]
    stripe = (torch.sin(height * 120) > 0).float()[:, None, None]
    denim = stripe * torch.tensor([0.15, 0.25, 0.5]) + (1 - stripe) * torch.tensor([0.3, 0.45, 0.7])
    ded.paint(legs, denim.expand(-1, nk, 3))
    arms = Selection.from_regions(body, "arms")
    f = donor.model.f_geo.detach()[arms.faces].clone().requires_grad_(True)
    opt = torch.optim.Adam([f], lr=0.05)
    for _ in range(100):  # maximise the arms' corner offsets: a loose sleeve
        out_ = donor.model.F_coarse(torch.cat([f, donor.model.pe[arms.faces]], -1))
        loss = -out_.mean() + 1e-3 * f.square().sum(1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        donor.model.f_geo[arms.faces] = f.detach()
    pair("transfer_trousers", front, lambda: ed.transfer(donor, legs, "tex", donor_name="donor"))
    pair("transfer_sleeves", left, lambda: ed.transfer(donor, arms, "geo", donor_name="donor"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
