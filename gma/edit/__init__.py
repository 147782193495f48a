"""Editing a GMA: selections, paint, stamp, cross-identity feature transfer, body shape, undo history.

Edits act on the feature layer (``f_geo``, ``f_tex``) and the body identity, never on surfels directly,
so an edited avatar still animates, re-poses and saves like a fitted one; decoders stay frozen.

    from gma.edit import Editor, Selection
    ed = Editor(avatar, body, ctx)                       # owns avatar, decoded surfels, history
    sel = Selection.from_regions(body, "torso")
    change = ed.paint(sel, "#c03030")                    # re-decodes the touched faces only
    change.rows                                          # surfel rows to rewrite on the GPU
    ed.undo(); ed.redo(); ed.avatar.save("out.gma")
"""

from gma.edit.editor import Change, Editor, summarize
from gma.edit.errors import EditError
from gma.edit.invert import InvertConfig, solve_features
from gma.edit.paint import paint_features, parse_color
from gma.edit.screen import ScreenView
from gma.edit.selection import FaceGraph, Selection, load_selection, mirror_map, save_selection
from gma.edit.stamp import StampPlacement, load_stamp_image, solid_shape
from gma.edit.transfer import check_shared_decoders, transfer_features
from gma.edit.views import NAMED_VIEWS, canonical_vertices, named_view, posed_vertices
from gma.render.face_id import FaceIdRenderer, IdImage, face_id_reference

__all__ = ["NAMED_VIEWS", "Change", "EditError", "Editor", "FaceGraph", "FaceIdRenderer", "IdImage", "InvertConfig",
           "ScreenView", "Selection", "StampPlacement", "canonical_vertices", "check_shared_decoders",
           "face_id_reference", "load_selection", "load_stamp_image", "mirror_map", "named_view", "paint_features",
           "parse_color", "posed_vertices", "save_selection", "solid_shape", "solve_features", "summarize",
           "transfer_features"]
