"""Shared pieces of the importers: safe loading of third-party ``.npy``/``.pkl`` files, resizing, and
streaming frames into a :class:`~gma.data.sequence.SequenceWriter` with a progress bar."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from PIL import Image
from tqdm import tqdm

from gma.body.params import RestrictedUnpickler, SequenceBody
from gma.data.cameras import Cameras
from gma.data.sequence import Sequence, SequenceWriter

__all__ = [
    "frame_range", "load_npy_safely", "mask_from_array", "read_rgb", "resize_frame", "scale_cameras",
    "write_imported",
]


def load_npy_safely(path: str | os.PathLike):
    """Load a ``.npy``; object arrays (ZJU-MoCap's pickled dicts) go through the restricted
    unpickler that only builds numpy arrays and builtins. Returns the array (0-d object arrays are
    unwrapped to the Python object they hold)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: file not found")
    with open(path, "rb") as f:
        try:
            version = np.lib.format.read_magic(f)
            if version == (1, 0):
                shape, fortran, dtype = np.lib.format.read_array_header_1_0(f)
            else:
                shape, fortran, dtype = np.lib.format.read_array_header_2_0(f)
        except ValueError as exc:
            raise ValueError(f"{path}: not a .npy file ({exc})") from exc
        if not dtype.hasobject:
            f.seek(0)
            return np.load(f, allow_pickle=False)
        try:
            arr = RestrictedUnpickler(f, encoding="latin1").load()
        except Exception as exc:
            raise ValueError(f"{path}: cannot be read safely ({exc})") from exc
    arr = np.asarray(arr, dtype=object)
    return arr.item() if arr.shape == () else arr


def read_rgb(path: Path) -> np.ndarray:
    """uint8 [H, W, 3] (grey expanded, alpha dropped)."""
    img = iio.imread(path)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, axis=2)
    return np.ascontiguousarray(img[..., :3])


def resize_frame(img: np.ndarray, mask: np.ndarray, factor: int) -> tuple[np.ndarray, np.ndarray]:
    """Shrink an image [H, W, 3] uint8 and mask [H, W] float in [0, 1] by an integer ``factor``
    (box filter, so a binary mask becomes a soft coverage mask)."""
    if factor == 1:
        return img, mask
    h, w = img.shape[0] // factor, img.shape[1] // factor
    small = Image.fromarray(img).resize((w, h), Image.Resampling.BOX)
    m = Image.fromarray(np.asarray(mask, np.float32), mode="F").resize((w, h), Image.Resampling.BOX)
    return np.asarray(small), np.clip(np.asarray(m), 0.0, 1.0)


def scale_cameras(cams: Cameras, factor: int) -> Cameras:
    """Cameras for images shrunk by ``factor`` (pixel (x, y) spans [x, x+1), so u' = u / factor)."""
    if factor == 1:
        return cams
    K = cams.K.copy()
    K[:, :2] /= factor
    return Cameras(cams.width // factor, cams.height // factor, K, cams.w2c)


def write_imported(
    out: str | os.PathLike,
    frames: Iterable[tuple[np.ndarray, np.ndarray]],
    count: int,
    cameras: Cameras,
    body: SequenceBody,
    splits: dict[str, list[int]] | None = None,
    downscale: int = 1,
    overwrite: bool = False,
    desc: str = "import",
    extra: Callable[[SequenceWriter], None] | None = None,
) -> Sequence:
    """Write ``count`` (image, mask) frames plus metadata as a sequence at ``out``, atomically."""
    if downscale < 1:
        raise ValueError(f"downscale must be a positive integer, got {downscale}")
    cams = scale_cameras(cameras, downscale)
    writer = SequenceWriter(out, cams.width, cams.height, overwrite=overwrite)
    try:
        for img, mask in tqdm(frames, total=count, desc=desc, unit="frame", leave=False):
            expected = (cameras.height, cameras.width)
            if img.shape[:2] != expected:
                raise ValueError(f"frame {writer.count}: image is {img.shape[1]}x{img.shape[0]}, cameras say "
                                 f"{cameras.width}x{cameras.height}")
            if mask.shape != expected:
                raise ValueError(f"frame {writer.count}: mask is {mask.shape[1]}x{mask.shape[0]}, image is "
                                 f"{img.shape[1]}x{img.shape[0]}")
            writer.add_frame(*resize_frame(img, mask, downscale))
        if writer.count != count:
            raise ValueError(f"expected {count} frames, got {writer.count}")
        writer.set_cameras(cams)
        writer.set_body(body)
        if splits:
            writer.set_splits(splits)
        if extra is not None:
            extra(writer)
    except BaseException:
        writer.abort()
        if hasattr(frames, "close"):  # a generator: its readers (a video's ffmpeg) end now, not with the traceback
            frames.close()
        raise
    return writer.close()


def frame_range(n: int, start: int = 0, end: int | None = None, skip: int = 1) -> list[int]:
    """Indices ``start, start+skip, ... < end`` of ``n`` source frames (``end`` None = all)."""
    if skip < 1 or start < 0:
        raise ValueError("start must be >= 0 and skip >= 1")
    stop = n if end is None else min(end, n)
    idx = list(range(start, stop, skip))
    if not idx:
        raise ValueError(f"frame range start={start} end={end} skip={skip} selects nothing of {n} frames")
    return idx


def mask_from_array(m: np.ndarray, source) -> np.ndarray:
    """Coverage float32 [H, W] from a uint8/bool/float mask of any common encoding (0/1, 0/255)."""
    m = np.asarray(m)
    if m.ndim == 3:
        m = m[..., 0]
    if m.dtype == bool:
        return m.astype(np.float32)
    if np.issubdtype(m.dtype, np.floating):
        return np.clip(m, 0, 1).astype(np.float32)
    mx = m.max(initial=0)
    if mx <= 1:
        return m.astype(np.float32)
    if m.dtype == np.uint8 or mx <= 255:
        return m.astype(np.float32) / 255.0
    raise ValueError(f"{source}: cannot interpret mask values up to {mx}")
