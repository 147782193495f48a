"""Before/after pictures of each edit for ``docs/editing.md`` (written by this script, not by hand): the
showcase of ``gma.edit.showcase`` — a painted sleeve, a logo stamped on the chest, and a second person's
trousers (texture and geometry) transferred across identities.

With ``--avatar`` and ``--donor`` (what ``gma demo`` writes: ``out/demo/avatar.gma`` and
``out/demo/donor.gma``, two synthetic people fitted with the same decoders) the pictures show real fits.
Without them it uses the tests' pseudo-fitted avatar (``tests/edit_helpers.py``) and a donor made from it
(another body shape, striped trousers painted per surfel), which takes seconds instead of a demo run.

    python benchmarks/edit_pictures.py [--avatar out/demo/avatar.gma --donor out/demo/donor.gma] [--out docs]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests")]


def pseudo_donor(av, body, ctx):
    """Another body shape with ``av``'s decoders and features, wearing striped trousers."""
    import torch

    from gma.avatar import Avatar
    from gma.edit import Editor, Selection

    donor = Avatar.create(av.config, body, torch.tensor((0.9, 0.3, 0.8, 0.9, 0.95, 0.4)))
    donor.model.load_state_dict(av.model.state_dict())
    ded = Editor(donor, body, ctx)
    legs = Selection.from_regions(body, "legs")
    verts = ded.named_view("front", 64, 64).vertices
    height = torch.from_numpy(verts[body.faces.numpy()].mean(1)[:, 2])[legs.faces]
    stripe = (torch.sin(height * 120) > 0).float()[:, None, None]
    denim = stripe * torch.tensor([0.15, 0.25, 0.5]) + (1 - stripe) * torch.tensor([0.3, 0.45, 0.7])
    ded.paint(legs, denim.expand(-1, av.config.fine_per_face, 3))
    return donor


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--avatar", help="a fitted .gma (default: a pseudo-fitted avatar)")
    ap.add_argument("--donor", help="a second person's .gma with the same decoders (default: made from --avatar)")
    ap.add_argument("--out", default=str(REPO / "docs"))
    ap.add_argument("--size", type=int, default=256)
    args = ap.parse_args()
    import numpy as np

    from gma.avatar import Avatar
    from gma.avatar.gpu import AvatarRenderer
    from gma.body import load_body
    from gma.edit import Editor
    from gma.edit.showcase import run_showcase
    from gma.gpu import get_context
    from gma.render.image_io import save_png

    ctx = get_context()
    body = load_body("anny")
    if args.avatar:
        av = Avatar.load(args.avatar, body)
    else:
        from edit_helpers import fitted_avatar

        av = fitted_avatar(body, feature_dim=32, fine_per_face=4, hidden=128)
    donor = Avatar.load(args.donor, body) if args.donor else pseudo_donor(av, body, ctx)
    out = Path(args.out)
    ed = Editor(av, body, ctx)
    renderer = AvatarRenderer(ctx, av, body, decoded=ed.decoded)

    def picture(edit, views, apply):
        view = views[edit.view]
        before = renderer.render(ed.params(), view.camera, (1.0, 1.0, 1.0))
        change = apply()
        renderer.update_rows(change.rows, change.mesh)
        after = renderer.render(ed.params(), view.camera, (1.0, 1.0, 1.0))
        save_png(out / f"edit_{edit.name}.png", np.concatenate([before, after], 1))
        print(f"wrote {out / f'edit_{edit.name}.png'}: {edit.title} ({len(change.faces)} faces)")
        return change

    run_showcase(ed, donor, args.size, picture)
    return 0


if __name__ == "__main__":
    sys.exit(main())
