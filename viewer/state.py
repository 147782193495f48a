"""The viewer's state and its action API, independent of the window: everything a panel, a mouse gesture
or a test can do (orbit, presets, playback, body sliders, selection, recording) is a method here; the
edit tools (selection, paint, stamp, transfer, history, save) are ``state.edit`` (:mod:`viewer.edit`)."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from gma.body.motions import MOTIONS
from gma.core.camera import Camera
from gma.core.errors import InputError
from gma.gpu import GpuContext
from gma.view import CameraPath, FrameRenderer, OrbitCamera, Scene, SurfelSource
from gma.view.controls import BodyControls, load_motion
from gma.view.record import Recorder
from viewer.edit import EditTools

__all__ = ["RecordSettings", "ViewerState"]


@dataclass
class RecordSettings:
    """Record panel settings: output size independent of the window."""

    out: str = "recording.mp4"
    width: int = 640
    height: int = 480
    fps: float = 30.0
    seconds: float = 4.0
    keys: CameraPath = field(default_factory=lambda: CameraPath([], []))
    key_spacing: float = 1.0  # seconds between keyframes added with "add key"


class ViewerState:
    """What the viewer shows and how it changes. ``presets`` are fixed cameras (e.g. a dataset's)."""

    def __init__(self, ctx: GpuContext, source: SurfelSource, presets: list[Camera] | None = None):
        self.ctx, self.source = ctx, source
        self.scene = Scene(source)
        self.renderer = FrameRenderer(ctx)
        self.orbit = OrbitCamera.framing(*source.bounds(), up_axis=source.up_axis)
        self.home = self.orbit.copy()
        self.presets = list(presets or [])
        self.preset: int | None = None  # index into presets while one is active
        self.controls = BodyControls(source) if getattr(source, "body", None) is not None else None
        self.record = RecordSettings()
        self.recorder: Recorder | None = None
        self.message = ""
        self.edit = EditTools(self) if getattr(source, "body", None) is not None else None
        self._motion_label = "canonical"

    # -- camera ---------------------------------------------------------------------------------------
    def camera(self, width: int, height: int) -> Camera:
        """The current view for a ``width`` x ``height`` image (a preset is rescaled to that size)."""
        if self.preset is not None:
            return self.presets[self.preset].resized(width, height)
        return self.orbit.camera(width, height)

    def orbit_by(self, dx: float, dy: float) -> None:
        self.preset = None
        self.orbit.orbit(dx, dy)

    def pan_by(self, dx: float, dy: float, height: int) -> None:
        self.preset = None
        self.orbit.pan(dx, dy, height)

    def zoom_by(self, steps: float) -> None:
        self.preset = None
        self.orbit.zoom(steps)

    def use_preset(self, index: int | None) -> None:
        if index is not None and not 0 <= index < len(self.presets):
            raise ValueError(f"camera preset {index} does not exist ({len(self.presets)} presets)")
        self.preset = index

    def reset_view(self) -> None:
        self.preset = None
        self.orbit = self.home.copy()

    # -- playback ---------------------------------------------------------------------------------------
    def play_motion(self, spec: str | None, frames: int = 120) -> None:
        """Play a built-in motion, a body.npz / sequence folder, or stop (None: canonical pose)."""
        if self.controls is None:
            raise ValueError("this source has no body to animate")
        self.controls.set_motion(None if spec is None else load_motion(spec, self.source.body, frames))
        self._motion_label = "canonical" if spec is None else spec if spec in MOTIONS else Path(spec).name

    @property
    def motion_label(self) -> str:
        """What plays, as the motion list names it: ``canonical``, a built-in motion or a file's name."""
        if self.controls is None or self.controls.motion is None:
            return "canonical"
        return self._motion_label

    def tick(self, dt: float) -> None:
        """Advance time by ``dt`` seconds (playback)."""
        if self.controls is not None:
            self.controls.advance(dt)

    # -- selection (delegated to the edit tools: only faces visible in the current view are hit) --------
    def _tools(self):
        if self.edit is None:
            raise InputError("selection needs a body mesh; this source is a plain surfel cloud")
        return self.edit

    def select_box(self, box, size: tuple[int, int], mode: str = "replace") -> np.ndarray:
        """Select the visible faces whose centres fall in the pixel box (x0, y0, x1, y1) of a ``size`` =
        (w, h) view. Returns the selected face ids."""
        self._tools().select_box(box, size, mode)
        return self.scene.selection

    def select_lasso(self, polygon, size: tuple[int, int], mode: str = "replace") -> np.ndarray:
        self._tools().select_lasso(polygon, size, mode)
        return self.scene.selection

    def select_part(self, name: str, mode: str = "replace") -> np.ndarray:
        """Select a coarse region (head, arms, ...) or a fine part label of the body."""
        self._tools().select_region(name, mode)
        return self.scene.selection

    def clear_selection(self) -> None:
        self._tools().clear()

    def invert_selection(self) -> None:
        self._tools().invert()

    def save_selection(self, path: str | Path) -> None:
        tools = self._tools()
        tools.selection.save(path, self.source.body.name)
        self.message = f"saved {len(tools.selection)} faces to {path}"

    def load_selection(self, path: str | Path, mode: str = "replace") -> None:
        from gma.edit import Selection

        body = self._tools().body
        try:
            sel = Selection.load(path, body.name, body.num_faces)
        except FileNotFoundError as exc:
            raise InputError(str(exc)) from None
        self.edit.set_selection(sel, mode)
        self.message = f"loaded {len(sel)} faces from {path}"

    # -- recording ---------------------------------------------------------------------------------------
    def add_record_key(self) -> None:
        keys = self.record.keys
        keys.add(self.orbit, keys.times[-1] + self.record.key_spacing if keys.times else 0.0)

    def start_recording(self) -> Recorder:
        """Begin recording the keyed camera path (a turntable from the current view when fewer than two
        keys) with the playing motion; advance with :meth:`record_step`."""
        rs = self.record
        path = rs.keys if len(rs.keys.keys) >= 2 else CameraPath.turntable(self.orbit, rs.seconds)
        frames = max(1, round(path.duration * rs.fps))
        ctl = self.controls
        start = ctl.frame if ctl is not None else 0

        def pose_at(i: int) -> None:
            if ctl is not None and ctl.motion is not None:
                ctl.scrub(start + round(i * ctl.motion.fps / rs.fps))

        self.recorder = Recorder(self.renderer, self.scene, rs.out, path, rs.width, rs.height, rs.fps, frames,
                                 pose_at)
        return self.recorder

    def record_step(self) -> float | None:
        """Render the next recorded frame; returns the progress, or None when not recording."""
        if self.recorder is None:
            return None
        p = self.recorder.step()
        if self.recorder.done:
            out = self.recorder.close()
            self.message = f"recorded {self.recorder.num_frames} frames to {out}"
            self.recorder = None
        return p
