"""Reading a user's video for the preprocessing pipeline: every frame decoded once, with errors that
name the file and say what is wrong (not a video, no frames, a truncated file)."""

from __future__ import annotations

import os
from contextlib import closing
from pathlib import Path

import numpy as np

from gma.core.errors import InputError
from gma.data.importers._common import frame_range
from gma.data.importers.video import count_frames, read_frames

__all__ = ["VideoError", "memory_budget", "read_video"]

# An import holds the decoded frames and about four times as much besides (masks in float32, the mask
# check, the fit's targets): a 38-frame 1080p import peaked at 2.34 GB, ~1.2 GB of it models and
# libraries, for 0.24 GB of frames. A sixth of the machine's memory for the frames leaves room for that.
MEMORY_SHARE = 1 / 6


def memory_budget(share: float = MEMORY_SHARE) -> int | None:
    """Bytes of decoded frames an import may hold: ``share`` of the machine's physical memory (None where
    the system does not say)."""
    try:
        return int(os.sysconf("SC_PHYS_PAGES") * os.sysconf("SC_PAGE_SIZE") * share)
    except (ValueError, OSError, AttributeError):
        return None


class VideoError(InputError):
    """A video that cannot be used; the message names the file and the problem."""


def read_video(path: str | os.PathLike, start: int = 0, end: int | None = None, skip: int = 1,
               max_frames: int | None = None, info: dict | None = None,
               max_bytes: int | None = None) -> tuple[np.ndarray, list[int]]:
    """Decode ``path`` and keep frames ``start:end:skip``.

    Returns (frames uint8 [T, H, W, 3], source frame indices [T]). Anything ffmpeg reads works
    (mp4, mov, webm, gif, ...); frames come upright and in SDR (an HDR clip is tone-mapped, and
    ``info["hdr"]`` names its transfer: see :func:`gma.data.importers.video.read_frames`; when every
    frame was selected and decoding reached the end of the clip, ``info["frames_total"]`` is its frame
    count). ``max_frames``
    and ``max_bytes`` (of decoded frames, e.g. :func:`memory_budget`) guard memory: a selection beyond
    either is an error that suggests ``--skip``/``--end``, raised as soon as the bytes run over (before
    the machine does).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: video not found")
    if path.stat().st_size == 0:
        raise VideoError(f"{path}: the file is empty")
    if skip < 1 or start < 0:
        frame_range(0, start, end, skip)  # its error, before any decoding
    # Only the selected frames are converted and kept (ffmpeg drops the others right after decoding them),
    # and decoding stops at ``end``: a phone's 30 s 4K clip is 900 frames of 25 MB, more memory than most
    # machines have, where every 8th frame of it is 2.2 GB.
    whole = start == 0 and skip == 1
    frames, idx, selected, decoded = [], [], 0, 0  # decoded: frames known decoded, up to the last one received
    info = {} if info is None else info
    try:
        # Closed when reading stops, also on an error: ffmpeg ends then, not when the traceback goes.
        with closing(read_frames(path, False, info, None if whole else (start, end, skip))) as stream:
            for k, img in enumerate(stream):
                i = start + k * skip  # the source frame: ffmpeg's select keeps exactly these
                selected, decoded = k + 1, i + 1
                if max_bytes is not None and selected * img.nbytes > max_bytes:
                    raise _too_big(path, img, max_bytes, info.get("frames_estimate"), start, end, skip)
                if max_frames is None or selected <= max_frames:
                    frames.append(img.copy())
                    idx.append(i)
                if end is not None and i + skip >= end:
                    break  # the selection's last frame: the rest of the clip need not be decoded
            else:
                if whole:
                    info["frames_total"] = decoded  # decoded to the end of the stream: the clip's frame count
    except InputError:
        raise
    except ValueError as exc:  # raised by read_frames when ffmpeg cannot open the file
        raise _undecodable(path, exc) from exc
    except (OSError, RuntimeError) as exc:
        # imageio-ffmpeg raises here when the stream ends early (a truncated download, say) —
        # after the frames it managed to decode.
        where = (f"after {decoded} frames" if whole or not decoded else
                 f"after frame {decoded - 1}, the last selected frame it decoded")
        raise VideoError(f"{path}: the video is damaged or truncated {where} ({_last_line(exc)})") from exc
    if not idx:
        # Nothing came out: an empty clip, or a selection past its end (which of the two needs the count).
        n = decoded if whole else _frame_count(path)
        if n == 0:
            raise VideoError(f"{path}: no frames could be decoded (not a video, or a truncated one)")
        try:
            frame_range(n, start, end, skip)  # raises: the range selects nothing of the n frames
        except ValueError as exc:
            raise VideoError(f"{path}: {exc}") from None
        raise VideoError(f"{path}: none of frames {start}:{end}:{skip} of {n} could be decoded (a damaged video)")
    if max_frames is not None and selected > max_frames:
        raise VideoError(f"{path}: {selected} frames selected, more than the limit {max_frames}; "
                         "use --skip or --end to select fewer")
    return np.stack(frames), idx


def _frame_count(path: Path) -> int:
    try:
        return count_frames(path)
    except ValueError as exc:
        raise _undecodable(path, exc) from exc


def _undecodable(path: Path, exc: ValueError) -> VideoError:
    return VideoError(f"{path}: cannot be decoded as a video: not a video file, or a truncated or damaged one "
                      f"(ffmpeg: {_last_line(exc)})")


def _too_big(path: Path, frame: np.ndarray, max_bytes: int, total: int | None, start: int, end: int | None,
             skip: int) -> VideoError:
    """The error for a selection whose decoded frames would pass ``max_bytes``, with a ``--skip`` that fits
    when the header says how many frames the clip has."""
    h, w = frame.shape[:2]
    fit = max(1, max_bytes // frame.nbytes)
    wanted = len(range(start, total if end is None else min(end, total), skip)) if total else None
    size = (f"{wanted} frames of {w}x{h} selected ({wanted * frame.nbytes / 2**30:.1f} GB decoded)" if wanted
            else f"more than {fit} frames of {w}x{h} selected")
    hint = f"--skip {skip * -(-wanted // fit)}" if wanted else "--skip"
    return VideoError(f"{path}: {size}, more than this machine's memory allows for an import ({fit} frames, "
                      f"{max_bytes / 2**30:.1f} GB); use {hint} or --end to select at most {fit}")


def _last_line(exc: BaseException) -> str:
    """The last non-empty line of an error (ffmpeg's banner before it says nothing useful)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip() and not ln.startswith("===")]
    return (lines[-1] if lines else type(exc).__name__).rstrip(")")
