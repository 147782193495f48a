"""The edits that show the method's point on any fitted avatar: a painted sleeve, a logo stamped on the
chest, cuffs painted on one arm and mirrored to the other, and a second person's trousers (texture and
geometry) transferred across identities. ``gma demo`` runs them after its fit, and
``benchmarks/edit_pictures.py`` draws their before/after pictures.

Each edit is an ordinary :class:`~gma.edit.Editor` operation: recorded in the avatar's history, undoable,
re-decoding only the faces it touches.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from gma.edit.editor import Change, Editor
from gma.edit.screen import ScreenView
from gma.edit.selection import Selection
from gma.edit.stamp import StampPlacement

__all__ = ["SHOWCASE", "ShowcaseEdit", "logo_image", "run_showcase"]

SLEEVE_COLOR = "#c03030"
LOGO_WIDTH_M = 0.18
CUFF_COLOR = "#f0c020"
CUFF_RINGS = 18  # rings of faces grown from the hand: the forearm next to the wrist


@dataclass
class ShowcaseEdit:
    """One edit of the showcase: ``name`` (file-name friendly), ``title`` (for a caption), the view it is
    best seen from ("front" or "left"), and ``apply(editor, views, donor) -> Change``."""

    name: str
    title: str
    view: str
    apply: Callable[[Editor, dict[str, ScreenView], object], Change]
    needs_donor: bool = False


def logo_image(size: int = 128) -> np.ndarray:
    """[size, size, 4] float RGBA: a yellow ring around a blue disc with a soft edge (a stand-in logo)."""
    yy, xx = (np.mgrid[0:size, 0:size] + 0.5) / size * 2 - 1
    rad = np.hypot(xx, yy)
    logo = np.zeros((size, size, 4), np.float32)
    logo[..., :3] = np.where((rad > 0.65)[..., None], [1.0, 0.85, 0.1], [0.1, 0.2, 0.8])
    logo[..., 3] = np.clip((1 - rad) * size / 2, 0, 1)
    return logo


def _left_sleeve(ed: Editor, view: ScreenView) -> Selection:
    """The arm on the image's right-hand side of the front view (the avatar's left arm)."""
    arms = Selection.from_regions(ed.body, "arms")
    centres_x = view.px[:, 0]
    right_half = torch.from_numpy(centres_x > view.camera.width / 2)
    return Selection.from_mask(arms.mask() & right_half)


def _paint_sleeve(ed: Editor, views: dict[str, ScreenView], donor) -> Change:
    return ed.paint(_left_sleeve(ed, views["front"]), SLEEVE_COLOR)


def _stamp_logo(ed: Editor, views: dict[str, ScreenView], donor) -> Change:
    front = views["front"]
    torso = ed.body.region_mask("torso").numpy() & front.visible
    # A little above the torso's visible centre: the chest rather than the belly.
    chest = front.px[torso].mean(0) - np.array([0.0, 0.06 * front.camera.height])
    return ed.stamp(logo_image(), front, StampPlacement(tuple(float(v) for v in chest), LOGO_WIDTH_M, "m"),
                    name="logo")


def _mirror_cuffs(ed: Editor, views: dict[str, ScreenView], donor) -> Change:
    # A band of the left forearm above the hand, and its mirror image on the right arm.
    hand = Selection.from_regions(ed.body, "hand.L")
    band = hand.grow(ed.graph, CUFF_RINGS).subtract(hand).intersect(Selection.from_regions(ed.body, "arms"))
    return ed.paint(band.symmetric(ed.mirror_map), CUFF_COLOR)


def _transfer_trousers(ed: Editor, views: dict[str, ScreenView], donor) -> Change:
    return ed.transfer(donor, Selection.from_regions(ed.body, "legs"), "both", donor_name="donor")


SHOWCASE = (
    ShowcaseEdit("paint_sleeve", f"painted sleeve (paint, left arm, {SLEEVE_COLOR})", "front", _paint_sleeve),
    ShowcaseEdit("stamp_logo", f"logo stamped on the chest (stamp, {LOGO_WIDTH_M} m, front view)", "front",
                 _stamp_logo),
    ShowcaseEdit("mirror_cuffs", f"cuffs painted on the left forearm and mirrored to the right (paint --mirror, "
                 f"{CUFF_COLOR})", "front", _mirror_cuffs),
    ShowcaseEdit("transfer_trousers", "a second person's trousers, texture and geometry (transfer --what both)",
                 "front", _transfer_trousers, needs_donor=True),
)


def run_showcase(ed: Editor, donor=None, size: int = 256, on_edit=None) -> list[tuple[ShowcaseEdit, Change]]:
    """Apply the showcase edits to ``ed`` (the transfer only when a ``donor`` avatar sharing its decoders is
    given). ``on_edit(edit, views, before_fn)`` is called around each edit for pictures: it receives the
    edit and the views, and must call ``before_fn()`` to apply it. Returns [(edit, change)]."""
    views = {name: ed.named_view(name, size, size) for name in ("front", "left")}
    done = []
    for edit in SHOWCASE:
        if edit.needs_donor and donor is None:
            continue
        if on_edit is None:
            change = edit.apply(ed, views, donor)
        else:
            change = on_edit(edit, views, lambda edit=edit: edit.apply(ed, views, donor))
        done.append((edit, change))
    return done
