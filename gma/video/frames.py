"""Reading a user's video for the preprocessing pipeline: every frame decoded once, with errors that
name the file and say what is wrong (not a video, no frames, a truncated file)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gma.core.errors import InputError
from gma.data.importers._common import frame_range
from gma.data.importers.video import read_frames

__all__ = ["VideoError", "read_video"]


class VideoError(InputError):
    """A video that cannot be used; the message names the file and the problem."""


def read_video(path: str | os.PathLike, start: int = 0, end: int | None = None, skip: int = 1,
               max_frames: int | None = None, info: dict | None = None) -> tuple[np.ndarray, list[int]]:
    """Decode ``path`` and keep frames ``start:end:skip``.

    Returns (frames uint8 [T, H, W, 3], source frame indices [T]). Anything ffmpeg reads works
    (mp4, mov, webm, gif, ...); frames come upright and in SDR (an HDR clip is tone-mapped, and
    ``info["hdr"]`` names its transfer: see :func:`gma.data.importers.video.read_frames`). ``max_frames``
    guards memory: more selected frames is an error that suggests ``--skip``/``--end``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: video not found")
    if path.stat().st_size == 0:
        raise VideoError(f"{path}: the file is empty")
    if skip < 1 or start < 0:
        frame_range(0, start, end, skip)  # its error, before any decoding
    # Only the selected frames are kept, and decoding stops at ``end``: a phone's 30 s 4K clip is 900
    # frames of 25 MB, more memory than most machines have, where every 8th frame of it is 2.2 GB.
    frames, idx, selected, n = [], [], 0, 0
    try:
        for img in read_frames(path, False, info):
            if n >= start and (n - start) % skip == 0:
                selected += 1
                if max_frames is None or selected <= max_frames:
                    frames.append(img.copy())
                    idx.append(n)
            n += 1
            if end is not None and n >= end:
                break
    except InputError:
        raise
    except ValueError as exc:  # raised by read_frames when ffmpeg cannot open the file
        raise VideoError(f"{path}: cannot be decoded as a video: not a video file, or a truncated or damaged one "
                         f"(ffmpeg: {_last_line(exc)})") from exc
    except (OSError, RuntimeError) as exc:
        # imageio-ffmpeg raises here when the stream ends early (a truncated download, say) —
        # after the frames it managed to decode.
        raise VideoError(f"{path}: the video is damaged or truncated after {n} frames "
                         f"({_last_line(exc)})") from exc
    if n == 0:
        raise VideoError(f"{path}: no frames could be decoded (not a video, or a truncated one)")
    if not idx:
        frame_range(n, start, end, skip)  # raises: the range selects nothing of the n frames
    if max_frames is not None and selected > max_frames:
        raise VideoError(f"{path}: {selected} frames selected, more than the limit {max_frames}; "
                         "use --skip or --end to select fewer")
    return np.stack(frames), idx


def _last_line(exc: BaseException) -> str:
    """The last non-empty line of an error (ffmpeg's banner before it says nothing useful)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip() and not ln.startswith("===")]
    return (lines[-1] if lines else type(exc).__name__).rstrip(")")
