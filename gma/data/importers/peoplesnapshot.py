"""PeopleSnapshot as preprocessed by InstantAvatar (``scripts/peoplesnapshot/preprocess_PeopleSnapshot.py``)::

    male-3-casual/
      cameras.npz         intrinsic [3, 3], extrinsic [4, 4] (OpenCV world->camera), height, width
      images/image_0000.png …
      masks/mask_0000.npy …   uint8 0/1 (PNG masks are accepted too)
      poses.npz           betas [10] or [1, 10], thetas [T, 72] (SMPL axis-angle), transl [T, 3]

(InstantAvatar's refined ``poses/anim_nerf_*.npz`` cover frame sub-ranges chosen in its configs; pass
``--poses poses/anim_nerf_train.npz --start/--end/--skip`` matching that config to use them.)

The body is SMPL (``model = "smpl"`` in ``body.npz``); the user's SMPL model file must exist because a
sequence is useless for fitting without it.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from gma.body.params import SequenceBody, find_model_file
from gma.data.cameras import Cameras
from gma.data.importers._common import frame_range, mask_from_array, read_rgb, write_imported
from gma.data.sequence import IMAGE_SUFFIXES, Sequence

__all__ = ["import_peoplesnapshot"]


def _load_npz(path: Path) -> dict[str, np.ndarray]:
    if not path.is_file():
        raise FileNotFoundError(
            f"{path}: not found (is this a PeopleSnapshot folder in InstantAvatar's layout?)"
        )
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}


def _smpl_params(path: Path) -> dict[str, np.ndarray]:
    p = _load_npz(path)
    if "thetas" in p:
        thetas = p["thetas"].reshape(len(p["thetas"]), -1)
        if thetas.shape[1] != 72:
            raise ValueError(f"{path}: 'thetas' has {thetas.shape[1]} values per frame, expected 72 (SMPL)")
        p["global_orient"], p["body_pose"] = thetas[:, :3], thetas[:, 3:]
    for key in ("betas", "global_orient", "body_pose", "transl"):
        if key not in p:
            raise ValueError(f"{path}: missing {key!r} (has {sorted(p)})")
    p["betas"] = p["betas"].reshape(-1, p["betas"].shape[-1])[0]
    return p


def _gender_from_name(name: str) -> str:
    low = name.lower()
    return "female" if low.startswith("female") else "male" if low.startswith("male") else "neutral"


def import_peoplesnapshot(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    poses: str = "poses.npz",
    start: int = 0,
    end: int | None = None,
    skip: int = 1,
    test_start: int | None = None,
    gender: str | None = None,
    smpl_dir: str | os.PathLike | None = None,
    downscale: int = 1,
    overwrite: bool = False,
) -> Sequence:
    """Import one PeopleSnapshot subject folder ``src`` into a sequence at ``out``.

    Source frames ``start:end:skip`` are kept; those at or after ``test_start`` go to the ``test`` split
    (the rest to ``train``). ``gender`` defaults to the folder name's prefix (male-/female-).
    """
    src = Path(src)
    if not src.is_dir():
        raise FileNotFoundError(f"{src}: PeopleSnapshot folder not found")
    gender = gender or _gender_from_name(src.name)
    find_model_file("smpl", gender, smpl_dir)  # fail before any work when the model is missing

    cam = _load_npz(src / "cameras.npz")
    for key in ("intrinsic", "extrinsic", "height", "width"):
        if key not in cam:
            raise ValueError(f"{src / 'cameras.npz'}: missing {key!r}")
    extr = np.asarray(cam["extrinsic"], np.float64)
    if extr.shape == (3, 4):
        extr = np.vstack([extr, [0, 0, 0, 1]])
    cams = Cameras(
        int(cam["width"]), int(cam["height"]), np.asarray(cam["intrinsic"], np.float64)[None], extr[None]
    )

    images = sorted(p for p in (src / "images").glob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
    if not images:
        raise FileNotFoundError(f"{src / 'images'}: no images")
    masks = sorted((src / "masks").glob("*.npy")) or sorted((src / "masks").glob("*.png"))
    if len(masks) != len(images):
        raise ValueError(f"{src / 'masks'}: {len(masks)} masks for {len(images)} images")
    params = _smpl_params(src / poses)
    n_pose = len(params["global_orient"])
    idx = frame_range(len(images), start, end, skip)
    if n_pose == len(images):
        rows = idx
    elif n_pose == len(idx):  # a refined pose file that covers exactly the selected frames
        rows = list(range(n_pose))
    else:
        raise ValueError(
            f"{src / poses}: {n_pose} frames of poses, but {len(images)} images "
            f"({len(idx)} selected by start/end/skip)"
        )
    body = SequenceBody(
        "smpl",
        {
            "betas": params["betas"].astype(np.float32),
            "global_orient": params["global_orient"][rows],
            "body_pose": params["body_pose"][rows],
            "transl": params["transl"][rows],
            "gender": np.asarray(gender),
        },
    )

    def frames():
        for i in idx:
            m = np.load(masks[i], allow_pickle=False) if masks[i].suffix == ".npy" else read_rgb(masks[i])
            yield read_rgb(images[i]), mask_from_array(m, masks[i])

    splits = None
    if test_start is not None:
        splits = {
            "train": [k for k, i in enumerate(idx) if i < test_start],
            "test": [k for k, i in enumerate(idx) if i >= test_start],
        }
    return write_imported(out, frames(), len(idx), cams, body, splits, downscale, overwrite, "PeopleSnapshot")
