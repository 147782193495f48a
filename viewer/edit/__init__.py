"""The viewer's edit tools, without a window: selection (box, lasso, brush, wand, regions, grow/shrink,
invert), paint (fill, brush strokes, eyedropper), stamp (image, placement, apply), transfer (donor
avatar), body shape "keep", history (undo / redo / revert) and save.

Every mouse gesture of the window and every panel widget calls a method of :class:`EditTools`, in pixel
coordinates of the current view, so tests and the benchmark drive exactly the code the mouse drives. All
edits go through :class:`gma.edit.Editor` (the only place edits happen); a :class:`gma.edit.Change` is
applied to the GPU by rewriting its rows only (:meth:`gma.view.source.BodySource.update_rows`): no full
re-upload, no new pipelines, and the frame loop (animation included) keeps running between and during
strokes.

A feature solve can take longer than a frame. With ``background`` (the window's setting) an edit runs on
a worker thread (:mod:`viewer.edit.worker`): its target colours are written to the touched rows of the
GPU colour buffer at once (a preview, visible on the next frame; the window starts the solve only after
presenting that frame, so the two do not share the CPU), the frame loop and the animation go on, and
:meth:`EditTools.poll` (once per frame) uploads the decoded result when the solve is done. One edit runs
at a time; every action that reads or writes the avatar waits for it first, so the editor is never used
from two threads at once. Tests and scripts that call the tools directly use the same code with
``background=False`` or call :meth:`EditTools.wait`.

Selections are made in a :class:`gma.edit.ScreenView` of what is on screen now (the posed mesh seen by
the current camera, with a face-ID render so that only visible faces are hit). The view is cached until
the camera, the window size or the pose changes, so a brush stroke renders IDs once, not per dab.

Modules: :mod:`~viewer.edit.session` (the shared state, running and previewing edits),
:mod:`~viewer.edit.worker` (the thread), :mod:`~viewer.edit.selection`, :mod:`~viewer.edit.paint`
(colour, fill, brush strokes), :mod:`~viewer.edit.stamp`, :mod:`~viewer.edit.transfer`,
:mod:`~viewer.edit.history` (undo, redo, save) and :mod:`~viewer.edit.tools` (them all on one object).
"""

from viewer.edit.history import merge_records
from viewer.edit.paint import BrushSettings, StrokeStats
from viewer.edit.stamp import StampState
from viewer.edit.tools import EditTools

__all__ = ["BrushSettings", "EditTools", "StampState", "StrokeStats", "merge_records"]
