"""Face selection for the viewer: re-exported from :mod:`gma.edit` (``gma.edit.screen`` for the
screen-space geometry, ``gma.edit.selection`` for the file), where the editing library owns it."""

from gma.edit.screen import face_centres_on_screen, faces_in_box, faces_in_lasso, points_in_polygon
from gma.edit.selection import FORMAT, SelectionFile, load_selection, save_selection

__all__ = ["FORMAT", "SelectionFile", "face_centres_on_screen", "faces_in_box", "faces_in_lasso", "load_selection",
           "points_in_polygon", "save_selection"]
