"""Recording a camera path and an animation offscreen, at a resolution independent of any window, to an
MP4 (imageio-ffmpeg, H.264), a GIF, or a folder of PNG frames.

:class:`Recorder` renders one frame per :meth:`Recorder.step` so that the viewer can keep its window
alive and show a progress bar; ``gma render`` simply loops. The output appears atomically: frames are
written under a temporary name that is renamed into place by :meth:`Recorder.close`.
"""

from __future__ import annotations

import os
import re
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

from gma.core.atomic import ordinary_mode, temp_prefix
from gma.core.errors import OutputError
from gma.core.outputs import prepare_output_dir, prepare_output_file
from gma.view.orbit import CameraPath
from gma.view.renderer import FrameRenderer, Scene

__all__ = ["Recorder", "not_a_frames_dir", "output_kind", "prepare_recording"]


FRAME_NAME = re.compile(r"\d{6}\.png")


def output_kind(path: str | Path) -> str:
    """"mp4", "gif", "png" (one still image) or "frames" (a directory) from the output path's suffix."""
    suffix = Path(path).suffix.lower()
    if suffix in (".mp4", ".gif", ".png"):
        return suffix[1:]
    if suffix == "":
        return "frames"
    raise ValueError(f"{path}: unsupported output; use .mp4, .gif, .png (one frame) or a directory name for PNG "
                     "frames")


def not_a_frames_dir(path: Path) -> str | None:
    """None when ``path`` holds only numbered PNG frames as the recorder writes them (so it may be replaced),
    else why not."""
    foreign = sorted(e.name for e in Path(path).iterdir() if not FRAME_NAME.fullmatch(e.name))
    return None if not foreign else f"it holds {', '.join(foreign[:3])}" + (" ..." if len(foreign) > 3 else "")


def prepare_recording(out: str | Path, force: bool = False) -> Path:
    """Check before rendering that ``out`` (a .mp4/.gif file or a folder of PNG frames) may be written."""
    if output_kind(out) == "frames":
        return prepare_output_dir(out, force, "folder of frames", not_a_frames_dir)
    return prepare_output_file(out, force, "video")


class Recorder:
    """Renders ``num_frames`` frames of ``scene`` along ``path`` at ``width`` x ``height`` and ``fps``.

    ``pose_at(i)`` is called before frame ``i`` to set the body pose (e.g. the playback's frame); it may
    be None for a still subject. ``background`` overrides the scene's background while recording."""

    def __init__(self, renderer: FrameRenderer, scene: Scene, out: str | Path, path: CameraPath, width: int,
                 height: int, fps: float = 30.0, num_frames: int | None = None,
                 pose_at: Callable[[int], None] | None = None):
        if width < 2 or height < 2:
            raise ValueError(f"recording size must be at least 2x2, got {width}x{height}")
        self.kind = output_kind(out)
        if self.kind == "mp4":
            # H.264 in yuv420p needs even sizes; round down rather than let ffmpeg rescale.
            width, height = width - width % 2, height - height % 2
        self.renderer, self.scene, self.out, self.path = renderer, scene, Path(out), path
        self.width, self.height, self.fps = int(width), int(height), float(fps)
        self.num_frames = int(num_frames if num_frames is not None else max(1, round(path.duration * fps) or 1))
        if self.kind == "png" and self.num_frames != 1:
            raise ValueError(f"{out}: a .png holds one frame, not {self.num_frames} (use --seconds 0, or .gif/.mp4)")
        self.pose_at = pose_at
        self.frame = 0
        self._gif_frames: list[np.ndarray] = []
        self.out.parent.mkdir(parents=True, exist_ok=True)
        if self.kind == "frames":
            self._tmp = Path(tempfile.mkdtemp(prefix=temp_prefix(self.out), suffix=".partial", dir=self.out.parent))
        else:
            fd, tmp = tempfile.mkstemp(prefix=temp_prefix(self.out), suffix=".tmp" + self.out.suffix,
                                       dir=self.out.parent)
            os.close(fd)
            self._tmp = Path(tmp)
        self._writer = None
        if self.kind == "mp4":
            import imageio.v2 as imageio

            self._writer = imageio.get_writer(self._tmp, format="FFMPEG", mode="I", fps=self.fps, codec="libx264",
                                              quality=8, macro_block_size=1, pixelformat="yuv420p")

    @property
    def progress(self) -> float:
        return self.frame / self.num_frames

    @property
    def done(self) -> bool:
        return self.frame >= self.num_frames

    def step(self) -> float:
        """Render and write the next frame; returns the progress in [0, 1]."""
        if self.done:
            return 1.0
        i = self.frame
        if self.pose_at is not None:
            self.pose_at(i)
        orbit = self.path.at(i / self.fps)
        image = self.renderer.render_image(self.scene, orbit.camera(self.width, self.height))[..., :3]
        if self.kind == "mp4":
            self._writer.append_data(image)
        elif self.kind in ("gif", "png"):
            self._gif_frames.append(image)
        else:
            import imageio.v3 as iio

            iio.imwrite(self._tmp / f"{i:06d}.png", image)
        self.frame += 1
        return self.progress

    def run(self, progress: Callable[[float], None] | None = None) -> Path:
        """Record every remaining frame and close; returns the output path."""
        while not self.done:
            p = self.step()
            if progress:
                progress(p)
        return self.close()

    def close(self) -> Path:
        """Finish the file and move it into place (an unfinished recording is discarded by :meth:`abort`)."""
        if self.kind == "mp4":
            self._writer.close()
        elif self.kind == "gif":
            import imageio.v3 as iio

            iio.imwrite(self._tmp, np.stack(self._gif_frames), extension=".gif", duration=1000.0 / self.fps, loop=0)
        elif self.kind == "png":
            import imageio.v3 as iio

            iio.imwrite(self._tmp, self._gif_frames[0], extension=".png")
        os.chmod(self._tmp, ordinary_mode(folder=self.kind == "frames"))
        if self.kind == "frames":
            if self.out.exists():
                why = not_a_frames_dir(self.out)
                if why is not None:  # never delete a folder that is not an earlier recording
                    self.abort()
                    raise OutputError(f"{self.out}: not replaced, it is not a folder of recorded frames ({why})")
                shutil.rmtree(self.out)
            os.replace(self._tmp, self.out)
        else:
            os.replace(self._tmp, self.out)
        return self.out

    def abort(self) -> None:
        if self._writer is not None:
            self._writer.close()
        if self._tmp.is_dir():
            shutil.rmtree(self._tmp, ignore_errors=True)
        else:
            self._tmp.unlink(missing_ok=True)
