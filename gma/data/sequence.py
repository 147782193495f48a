"""The sequence format of docs/design.md — reading with validation, and writing atomically.

::

  seq/
    images/000000.png …   RGB or RGBA, all the same size
    masks/000000.png …    optional when images are RGBA; 0 = background, 255 = person (soft values =
                          partial coverage at the silhouette edge)
    cameras.json          see gma.data.cameras
    body.npz              see gma.body.params
    splits.json           optional; see SPLIT_KEYS

``splits.json`` maps split names to frame indices. Known names: ``train`` (fit on these), ``test``
(generic held-out frames), ``test_pose`` (held-out novel poses: poses never seen in training),
``test_view`` (held-out novel camera views of training-like poses). Missing file: all frames train.

Validation names the offending file and the problem, so ``gma fit`` fails before any work is done.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from PIL import Image

from gma.body.params import SequenceBody, load_body, require_body_model, save_body
from gma.core.atomic import atomic_dir, atomic_write_json
from gma.core.errors import InputError
from gma.core.images import read_image
from gma.core.outputs import prepare_output_dir
from gma.data.cameras import Cameras, load_cameras, save_cameras, validate_cameras

__all__ = ["REQUIRED_ENTRIES", "SEQUENCE_ENTRIES", "SPLIT_KEYS", "Sequence", "SequenceWriter", "not_a_sequence",
           "prepare_sequence_output", "read_sequence"]

SPLIT_KEYS = ("train", "test", "test_pose", "test_view")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


# Smaller frames cannot hold a person (and come from typos such as --downscale 1000).
MIN_IMAGE_SIDE = 16

def _list_images(folder: Path) -> list[Path]:
    return sorted(p for p in folder.iterdir()
                  if p.suffix.lower() in IMAGE_SUFFIXES and not p.name.startswith("."))


@dataclass
class Sequence:
    """A validated sequence on disk. Images and masks are read lazily, one frame at a time.

    ``image(i)`` is uint8 [H, W, 3]; ``mask(i)`` float32 [H, W] in [0, 1] (coverage); ``cameras.frame(i)``
    gives (K [3, 3], w2c [4, 4]); ``body.frame(i)`` the body parameters of frame i.
    """

    root: Path
    image_paths: list[Path]
    mask_paths: list[Path] | None  # None: the mask is the images' alpha channel
    cameras: Cameras
    body: SequenceBody
    splits: dict[str, list[int]] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.image_paths)

    @property
    def width(self) -> int:
        return self.cameras.width

    @property
    def height(self) -> int:
        return self.cameras.height

    def split(self, name: str) -> list[int]:
        """Frame indices of split ``name`` (``[]`` when the sequence has no such split)."""
        return list(self.splits.get(name, []))

    def _read(self, path: Path) -> np.ndarray:
        """The image at ``path`` as float32 [H, W] or [H, W, C] in [0, 1], whatever its bit depth."""
        try:
            img = read_image(path)
        except (OSError, ValueError, SyntaxError) as exc:  # truncated or corrupt files
            raise InputError(f"{path}: cannot be read as an image (truncated or damaged? {exc})") from None
        if img.shape[:2] != (self.height, self.width):
            raise InputError(f"{path}: image is {img.shape[1]}x{img.shape[0]}, cameras.json says "
                             f"{self.width}x{self.height}")
        return to_unit_range(img, path)

    def image(self, i: int) -> np.ndarray:
        """Frame ``i`` as uint8 [H, W, 3] (alpha dropped; 16-bit files are rounded to 8 bits)."""
        img = self._read(self.image_paths[i])
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, axis=2)
        return np.ascontiguousarray(np.round(img[..., :3] * 255.0).astype(np.uint8))

    def mask(self, i: int) -> np.ndarray:
        """Person coverage of frame ``i``, float32 [H, W] in [0, 1]."""
        if self.mask_paths is None:
            img = self._read(self.image_paths[i])
            if img.ndim != 3 or img.shape[2] != 4:
                raise InputError(f"{self.image_paths[i]}: has no alpha channel and the sequence has no masks folder")
            return np.ascontiguousarray(img[..., 3])
        m = self._read(self.mask_paths[i])
        if m.ndim == 3:
            m = m[..., 0]
        return np.ascontiguousarray(m)


def to_unit_range(img: np.ndarray, path) -> np.ndarray:
    """Integer pixels of any bit depth (8-bit, 16-bit PNG) or booleans to float32 in [0, 1]."""
    if img.dtype == np.bool_:
        return img.astype(np.float32)
    if img.dtype == np.uint8:
        return img.astype(np.float32) / 255.0
    if img.dtype == np.uint16:
        return img.astype(np.float32) / 65535.0
    raise InputError(f"{path}: pixels of type {img.dtype} are not supported; save it as an 8- or 16-bit PNG or JPEG")


def _check_frames(root: Path) -> tuple[list[Path], list[Path] | None, tuple[int, int]]:
    img_dir = root / "images"
    if not img_dir.is_dir():
        raise FileNotFoundError(f"{img_dir}: missing images folder")
    images = _list_images(img_dir)
    if not images:
        raise ValueError(f"{img_dir}: no .png/.jpg images")
    size = None
    modes = set()
    for p in images:
        try:
            with Image.open(p) as im:  # reads the header only
                s, mode = im.size, im.mode
        except Exception as exc:  # PIL raises many kinds for a broken header
            raise InputError(f"{p}: not a readable image ({exc})") from None
        if size is None:
            size = s
            if min(s) < MIN_IMAGE_SIDE:
                raise InputError(f"{p}: image is {s[0]}x{s[1]}, too small to fit an avatar to (at least "
                                 f"{MIN_IMAGE_SIDE} pixels per side)")
        elif s != size:
            raise ValueError(f"{p}: image is {s[0]}x{s[1]} but {images[0].name} is {size[0]}x{size[1]}; "
                             "all frames must have the same size")
        modes.add(mode)
    mask_dir = root / "masks"
    masks = None
    if mask_dir.is_dir():
        masks = _list_images(mask_dir)
        if len(masks) != len(images):
            raise ValueError(f"{mask_dir}: {len(masks)} masks for {len(images)} images")
        for ip, mp in zip(images, masks, strict=True):
            if ip.stem != mp.stem:
                raise ValueError(f"{mp}: mask name does not match image {ip.name}")
            with Image.open(mp) as im:
                if im.size != size:
                    raise ValueError(f"{mp}: mask is {im.size[0]}x{im.size[1]}, "
                                     f"images are {size[0]}x{size[1]}")
    elif modes != {"RGBA"}:
        raise FileNotFoundError(f"{mask_dir}: missing masks folder, and the images have no alpha channel "
                                f"(modes {sorted(modes)})")
    return images, masks, size


def _load_splits(path: Path, n: int) -> dict[str, list[int]]:
    if not path.is_file():
        return {"train": list(range(n))}
    try:
        raw = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(raw, dict):
        raise ValueError(f"{path}: expected an object mapping split names to frame index lists")
    out = {}
    for key, idx in raw.items():
        if not isinstance(idx, list) or not all(isinstance(i, int) and not isinstance(i, bool) for i in idx):
            raise ValueError(f"{path}: split {key!r} must be a list of integer frame indices")
        bad = [i for i in idx if not 0 <= i < n]
        if bad:
            raise ValueError(f"{path}: split {key!r} has frame index {bad[0]} outside 0..{n - 1}")
        if len(set(idx)) != len(idx):
            raise ValueError(f"{path}: split {key!r} lists a frame twice")
        out[key] = idx
    return out


def read_sequence(path: str | os.PathLike, check_body_model: bool = True,
                  model_dir: str | os.PathLike | None = None) -> Sequence:
    """Open and validate the sequence at ``path``.

    Checks: images exist and share one size; masks (or alpha) exist, match image names and size;
    ``cameras.json`` and ``body.npz`` have the right shapes, finite values and the same frame count;
    ``splits.json`` indices are in range; and (``check_body_model``) the body model is installed —
    ``model_dir`` points at user SMPL / SMPL-X files (else ``$GMA_SMPLX_DIR`` / ``$GMA_SMPL_DIR``).
    Raises ``FileNotFoundError`` or ``ValueError`` naming the file and the problem.
    """
    root = Path(path)
    if not root.is_dir():
        raise FileNotFoundError(f"{root}: sequence directory not found")
    images, masks, (w, h) = _check_frames(root)
    n = len(images)
    cams = load_cameras(root / "cameras.json", num_frames=n)
    if (cams.width, cams.height) != (w, h):
        raise ValueError(f"{root / 'cameras.json'}: says {cams.width}x{cams.height} "
                         f"but the images are {w}x{h}")
    body_path = root / "body.npz"
    body = load_body(body_path, num_frames=n)
    if check_body_model:
        require_body_model(body, str(body_path), model_dir)
    splits = _load_splits(root / "splits.json", n)
    return Sequence(root, images, masks, cams, body, splits)


def _to_uint8(a: np.ndarray, name: str) -> np.ndarray:
    a = np.asarray(a)
    if a.dtype == np.uint8:
        return a
    if np.issubdtype(a.dtype, np.floating):
        if not np.all(np.isfinite(a)):
            raise ValueError(f"{name} holds non-finite values")
        return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
    raise ValueError(f"{name} has dtype {a.dtype}; expected uint8 or float in [0, 1]")


# What every sequence folder holds (the rest of SEQUENCE_ENTRIES is optional).
REQUIRED_ENTRIES = ("cameras.json", "body.npz", "images")
# What a sequence folder written by GMA holds (the format's files and what synth / the video import add).
SEQUENCE_ENTRIES = {"images", "masks", "cameras.json", "body.npz", "splits.json", "gt_mesh.npz", "gt_texture.png",
                    "synth.json", "video_report.json", "video_contact_sheet.png"}


def not_a_sequence(path: Path) -> str | None:
    """None when the folder ``path`` is a sequence as GMA writes them (so ``--force`` may replace it);
    otherwise why it is not (missing format files, or other files that replacing it would delete)."""
    entries = {e.name for e in Path(path).iterdir()}
    missing = [n for n in REQUIRED_ENTRIES if n not in entries]
    if missing:
        return f"no {', '.join(missing)}"
    foreign = sorted(entries - SEQUENCE_ENTRIES)
    if foreign:
        shown = ", ".join(foreign[:3]) + (f" and {len(foreign) - 3} more" if len(foreign) > 3 else "")
        return f"it also holds {shown}"
    return None


def prepare_sequence_output(out: str | os.PathLike, force: bool = False) -> Path:
    """Check before any work that ``out`` may receive a sequence: a new folder, or with ``force`` an
    existing sequence (never another folder). Raises :class:`gma.core.errors.OutputError`."""
    return prepare_output_dir(out, force, "sequence", not_a_sequence)


class SequenceWriter:
    """Writes a sequence into a hidden temporary directory and moves it into place on :meth:`close`
    (or the end of a ``with`` block) after validating it; on an error nothing appears at ``out``.

    Usage::

        with SequenceWriter(out, width, height) as w:
            for img, mask in frames:
                w.add_frame(img, mask)         # uint8 or float [H, W, 3], mask [H, W]
            w.set_cameras(cameras)
            w.set_body(body)
            w.set_splits({"train": [...], "test_pose": [...]})
            np.savez(w.path("gt_mesh.npz"), ...)  # extra files go in the same directory
    """

    def __init__(self, out: str | os.PathLike, width: int, height: int, overwrite: bool = False,
                 check_body_model: bool = False):
        self.out = Path(out)
        self.width, self.height = int(width), int(height)
        if min(self.width, self.height) < MIN_IMAGE_SIDE:
            raise InputError(f"{self.out}: frames of {self.width}x{self.height} are too small to fit an avatar to "
                             f"(at least {MIN_IMAGE_SIDE} pixels per side; is --downscale too large?)")
        self.check_body_model = check_body_model
        prepare_sequence_output(self.out, overwrite)
        self._ctx = atomic_dir(self.out, overwrite=overwrite)
        self._tmp = self._ctx.__enter__()
        (self._tmp / "images").mkdir()
        (self._tmp / "masks").mkdir()
        self.count = 0
        self._cameras: Cameras | None = None
        self._body: SequenceBody | None = None
        self._splits: dict | None = None
        self._closed = False

    def path(self, name: str) -> Path:
        """Where to write an extra file ``name`` so that it lands inside the finished sequence."""
        return self._tmp / name

    def add_frame(self, image: np.ndarray, mask: np.ndarray) -> int:
        """Append one frame: image [H, W, 3] and mask [H, W] (uint8, or float in [0, 1]); returns
        its index."""
        image = _to_uint8(image, f"frame {self.count} image")
        mask = _to_uint8(mask, f"frame {self.count} mask")
        if image.shape != (self.height, self.width, 3):
            raise ValueError(f"frame {self.count}: image shape {image.shape}, "
                             f"expected ({self.height}, {self.width}, 3)")
        if mask.shape != (self.height, self.width):
            raise ValueError(f"frame {self.count}: mask shape {mask.shape}, "
                             f"expected ({self.height}, {self.width})")
        name = f"{self.count:06d}.png"
        iio.imwrite(self._tmp / "images" / name, image)
        iio.imwrite(self._tmp / "masks" / name, mask)
        self.count += 1
        return self.count - 1

    def set_cameras(self, cameras: Cameras) -> None:
        validate_cameras(cameras, "cameras")
        if (cameras.width, cameras.height) != (self.width, self.height):
            raise ValueError(f"cameras are {cameras.width}x{cameras.height}, "
                             f"frames are {self.width}x{self.height}")
        self._cameras = cameras

    def set_body(self, body: SequenceBody) -> None:
        self._body = body

    def set_splits(self, splits: dict[str, list[int]]) -> None:
        self._splits = {k: [int(i) for i in v] for k, v in splits.items()}

    def close(self) -> Sequence:
        """Write metadata, validate the whole directory, and move it to ``out``. Returns the sequence."""
        if self._closed:
            raise RuntimeError("SequenceWriter already closed")
        self._closed = True
        try:
            if self._cameras is None or self._body is None:
                raise ValueError(f"{self.out}: cameras and body parameters must be set before closing")
            if self.count == 0:
                raise ValueError(f"{self.out}: no frames were added")
            save_cameras(self._tmp / "cameras.json", self._cameras)
            save_body(self._tmp / "body.npz", self._body)
            if self._splits is not None:
                atomic_write_json(self._tmp / "splits.json", self._splits)
            read_sequence(self._tmp, check_body_model=self.check_body_model)
        except BaseException as exc:
            self._ctx.__exit__(type(exc), exc, exc.__traceback__)
            raise
        self._ctx.__exit__(None, None, None)
        return read_sequence(self.out, check_body_model=False)

    def abort(self) -> None:
        """Throw away everything written so far."""
        if not self._closed:
            self._closed = True
            err = RuntimeError("aborted")
            try:
                self._ctx.__exit__(RuntimeError, err, None)
            except RuntimeError:
                pass

    def __enter__(self) -> SequenceWriter:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        if exc_type is None:
            self.close()
        else:
            self.abort()
