"""X-Humans (Shen et al., X-Avatar, CVPR 2023). One take::

    00016/train/Take4/
      render/image/color_000001.png …
      render/depth/depth_000001.tiff …   optional; the mask is "depth < background depth"
      render/cameras.npz                 intrinsic [3, 3], extrinsic [T, 3, 4] or [T, 4, 4] (OpenCV w2c)
      SMPLX/mesh-f00001_smplx.pkl …      per-frame SMPL-X parameters (a pickled dict)

``src`` may be one take, or a subject folder (``00016/`` with ``train/Take*`` and ``test/Take*``): then
every take is imported, train takes into the ``train`` split and test takes into ``test_pose`` (X-Humans
is a pose-generalisation benchmark). ``gender.txt`` in the subject folder sets the gender if present.

The ``.pkl`` files are read with a restricted unpickler that only builds numpy arrays and builtins, so a
tampered download cannot run code; GMA never writes pickles itself.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from PIL import Image

from gma.body.params import SequenceBody, find_model_file, restricted_pickle_load
from gma.data.cameras import Cameras
from gma.data.importers._common import read_rgb, write_imported
from gma.data.sequence import Sequence

__all__ = ["import_xhumans"]

_SMPLX_KEYS = {
    "global_orient": 3,
    "body_pose": 63,
    "jaw_pose": 3,
    "leye_pose": 3,
    "reye_pose": 3,
    "left_hand_pose": 45,
    "right_hand_pose": 45,
    "transl": 3,
}
_NUM = re.compile(r"(\d+)")


def _frame_number(path: Path) -> int:
    nums = _NUM.findall(path.stem)
    if not nums:
        raise ValueError(f"{path}: no frame number in the file name")
    return int(nums[0])


def _takes(src: Path) -> list[tuple[Path, str]]:
    if (src / "render").is_dir():
        return [(src, "train")]
    takes = []
    for split_dir, split in (("train", "train"), ("test", "test_pose")):
        takes += [(t, split) for t in sorted((src / split_dir).glob("Take*")) if (t / "render").is_dir()]
    if not takes:
        raise FileNotFoundError(
            f"{src}: neither an X-Humans take (render/, SMPLX/) nor a subject folder "
            "with train/Take*/ and test/Take*/"
        )
    return takes


def _read_take(take: Path):
    img_dir, smplx_dir = take / "render" / "image", take / "SMPLX"
    images = sorted(img_dir.glob("*.png"), key=_frame_number)
    if not images:
        raise FileNotFoundError(f"{img_dir}: no images")
    pkls = {_frame_number(p): p for p in smplx_dir.glob("*.pkl")}
    cam_path = take / "render" / "cameras.npz"
    if not cam_path.is_file():
        raise FileNotFoundError(f"{cam_path}: camera file not found")
    with np.load(cam_path, allow_pickle=False) as c:
        K, extr = np.asarray(c["intrinsic"], np.float64), np.asarray(c["extrinsic"], np.float64)
    if extr.ndim == 2:
        extr = np.repeat(extr[None], len(images), axis=0)
    if extr.shape[1:] == (3, 4):
        extr = np.concatenate([extr, np.tile([[[0, 0, 0, 1.0]]], (len(extr), 1, 1))], axis=1)
    if extr.shape != (len(images), 4, 4) or K.shape != (3, 3):
        raise ValueError(
            f"{cam_path}: extrinsic {list(extr.shape)} / intrinsic {list(K.shape)} do not fit "
            f"{len(images)} images (expected [T, 3, 4] and [3, 3])"
        )
    params = []
    for img in images:
        n = _frame_number(img)
        if n not in pkls:
            raise FileNotFoundError(f"{smplx_dir}: no SMPL-X parameters for frame {n} ({img.name})")
        raw = restricted_pickle_load(pkls[n])
        if not isinstance(raw, dict):
            raise ValueError(f"{pkls[n]}: expected a dict of SMPL-X parameters")
        row = {}
        for key, size in _SMPLX_KEYS.items():
            v = np.asarray(raw.get(key, np.zeros(size)), np.float64).reshape(-1)
            if v.size != size:
                raise ValueError(
                    f"{pkls[n]}: {key!r} has {v.size} values, expected {size}"
                    + (" (PCA hand pose is not supported)" if "hand" in key else "")
                )
            row[key] = v
        row["betas"] = np.asarray(raw["betas"], np.float64).reshape(-1)
        row["expression"] = np.asarray(raw.get("expression", np.zeros(10)), np.float64).reshape(-1)
        params.append(row)
    depth_dir = take / "render" / "depth"
    depths = {_frame_number(p): p for p in depth_dir.glob("*.tiff")} if depth_dir.is_dir() else {}
    return images, K, extr, params, depths


def _mask(img_path: Path, img: np.ndarray, depths: dict[int, Path]) -> np.ndarray:
    d_path = depths.get(_frame_number(img_path))
    if d_path is not None:
        with Image.open(d_path) as im:  # Pillow reads X-Humans' float32 TIFFs without extra packages
            d = np.asarray(im, np.float64)
        if d.ndim == 3:
            d = d[..., 0]
        return (d < d.max()).astype(np.float32)  # background is rendered at the far value
    # Without depth: the renders have a flat black background.
    return (img.max(axis=2) > 0).astype(np.float32)


def import_xhumans(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    gender: str | None = None,
    smplx_dir: str | os.PathLike | None = None,
    skip: int = 1,
    downscale: int = 1,
    overwrite: bool = False,
) -> Sequence:
    """Import an X-Humans take or subject folder ``src`` (every ``skip``-th frame) to a sequence ``out``."""
    src = Path(src)
    if not src.is_dir():
        raise FileNotFoundError(f"{src}: X-Humans folder not found")
    if gender is None:
        for cand in (src / "gender.txt", src.parent.parent / "gender.txt"):
            if cand.is_file():
                gender = cand.read_text().strip().lower()
                break
    gender = gender or "neutral"
    find_model_file("smplx", gender, smplx_dir)
    if skip < 1:
        raise ValueError("skip must be >= 1")

    entries, Ks, w2cs, rows, splits = [], [], [], [], {}
    for take, split in _takes(src):
        images, K, extr, params, depths = _read_take(take)
        for i in range(0, len(images), skip):
            splits.setdefault(split, []).append(len(entries))
            entries.append((images[i], depths))
            Ks.append(K)
            w2cs.append(extr[i])
            rows.append(params[i])
    betas = rows[0]["betas"]
    for r, (img, _) in zip(rows, entries, strict=True):
        if r["betas"].shape != betas.shape or not np.allclose(r["betas"], betas, atol=1e-4):
            raise ValueError(
                f"{img}: body shape (betas) differs from the first frame's; one sequence must show one person"
            )
    e = max(len(r["expression"]) for r in rows)
    arrays = {k: np.stack([r[k] for r in rows]) for k in _SMPLX_KEYS}
    arrays["expression"] = np.stack([np.pad(r["expression"], (0, e - len(r["expression"]))) for r in rows])
    arrays["betas"] = betas
    arrays["gender"] = np.asarray(gender)
    body = SequenceBody("smplx", arrays)
    first = read_rgb(entries[0][0])
    cams = Cameras(first.shape[1], first.shape[0], np.stack(Ks), np.stack(w2cs))

    def frames():
        for img_path, depths in entries:
            img = read_rgb(img_path)
            yield img, _mask(img_path, img, depths)

    return write_imported(out, frames(), len(entries), cams, body, splits, downscale, overwrite, "X-Humans")
