"""ZJU-MoCap (Peng et al., Neural Body, CVPR 2021), e.g. ``CoreView_377/``::

    annots.npy            {"cams": {"K", "R", "T" (millimetres), "D"} per view,
                           "ims": [{"ims": ["Camera_B1/000000.jpg", …one per view]} per frame]}
    Camera_B1/000000.jpg …
    mask/Camera_B1/000000.png …   (or mask_cihp/…); any non-zero value is the person
    params/0.npy …        {"poses" [1, 72], "Rh" [1, 3], "Th" [1, 3], "shapes" [1, 10]} (EasyMocap SMPL)

EasyMocap poses the SMPL mesh about the world origin: ``v = R(Rh) · SMPL(poses, shapes) + Th``, whereas
SMPL's own ``global_orient``/``transl`` rotate about the root joint J0. Converting needs J0 for the
subject's shape, i.e. the user's SMPL model file: ``global_orient = Rh ∘ poses[:3]``,
``transl = Th + R(Rh)·J0 − J0``.

Monocular protocol: training frames come from one camera (``view``); novel-view test frames are taken
from ``test_views`` every ``test_every`` frames. ``annots.npy`` and the params are pickled numpy object
arrays; they are read with a restricted unpickler (numpy arrays and builtins only). Lens distortion
``D`` is ignored (ZJU's is small); images are used as they are.
"""

from __future__ import annotations

import os
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from gma.body.params import SequenceBody, find_model_file, load_smpl_model_arrays, smpl_root_joint
from gma.data.cameras import Cameras
from gma.data.importers._common import frame_range, load_npy_safely, read_rgb, write_imported
from gma.data.sequence import Sequence

__all__ = ["import_zjumocap"]


def _rotvec_to_matrix(r: np.ndarray) -> np.ndarray:
    theta = np.linalg.norm(r)
    if theta < 1e-12:
        return np.eye(3)
    k = r / theta
    kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + np.sin(theta) * kx + (1 - np.cos(theta)) * kx @ kx


def _matrix_to_rotvec(m: np.ndarray) -> np.ndarray:
    """Axis-angle [3] of a rotation matrix, through a unit quaternion (Shepperd's method: pick the
    largest of w, x, y, z to divide by, which stays accurate near 180°)."""
    tr = np.trace(m)
    cands = [tr, m[0, 0], m[1, 1], m[2, 2]]
    i = int(np.argmax(cands))
    if i == 0:
        w = np.sqrt(1 + tr) / 2
        q = np.array(
            [w, (m[2, 1] - m[1, 2]) / (4 * w), (m[0, 2] - m[2, 0]) / (4 * w), (m[1, 0] - m[0, 1]) / (4 * w)]
        )
    else:
        a, b, c = i - 1, i % 3, (i + 1) % 3
        x = np.sqrt(max(1 + m[a, a] - m[b, b] - m[c, c], 0.0)) / 2
        q = np.zeros(4)
        q[0] = (m[c, b] - m[b, c]) / (4 * x)
        q[1 + a] = x
        q[1 + b] = (m[a, b] + m[b, a]) / (4 * x)
        q[1 + c] = (m[a, c] + m[c, a]) / (4 * x)
    if q[0] < 0:
        q = -q
    s = np.linalg.norm(q[1:])
    if s < 1e-12:
        return np.zeros(3)
    return q[1:] / s * 2 * np.arctan2(s, q[0])


def _load_params(root: Path, params_dir: str, frame: int) -> dict[str, np.ndarray]:
    path = root / params_dir / f"{frame}.npy"
    p = load_npy_safely(path)
    if not isinstance(p, dict):
        raise ValueError(f"{path}: expected a dict with poses, Rh, Th, shapes")
    out = {}
    for key, size in (("poses", 72), ("Rh", 3), ("Th", 3), ("shapes", 10)):
        if key not in p:
            raise ValueError(f"{path}: missing {key!r}")
        v = np.asarray(p[key], np.float64).reshape(-1)
        if (key == "shapes" and v.size < 1) or (key != "shapes" and v.size != size):
            raise ValueError(f"{path}: {key!r} has {v.size} values, expected {size}")
        out[key] = v
    return out


def import_zjumocap(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    view: int = 0,
    test_views: list[int] | None = None,
    test_every: int = 30,
    start: int = 0,
    end: int | None = None,
    skip: int = 1,
    params_dir: str = "params",
    smpl_dir: str | os.PathLike | None = None,
    downscale: int = 1,
    overwrite: bool = False,
) -> Sequence:
    """Import a ZJU-MoCap subject ``src``: frames ``start:end:skip`` of camera ``view`` as ``train``,
    and frames every ``test_every`` (within the same range) of ``test_views`` (default: three views
    spread around the subject) as ``test_view``."""
    src = Path(src)
    if not src.is_dir():
        raise FileNotFoundError(f"{src}: ZJU-MoCap folder not found")
    smpl = load_smpl_model_arrays(find_model_file("smpl", "neutral", smpl_dir))
    annots = load_npy_safely(src / "annots.npy")
    if not isinstance(annots, dict) or "cams" not in annots or "ims" not in annots:
        raise ValueError(f"{src / 'annots.npy'}: expected a dict with 'cams' and 'ims'")
    Ks, w2c = _cameras(annots["cams"], src / "annots.npy")
    n_views = len(Ks)
    if not 0 <= view < n_views:
        raise ValueError(f"view {view} out of range: {src / 'annots.npy'} has {n_views} cameras")
    if test_views is None:
        test_views = sorted({(view + n_views * k // 4) % n_views for k in (1, 2, 3)} - {view})
    bad = [v for v in test_views if not 0 <= v < n_views]
    if bad:
        raise ValueError(f"test view {bad[0]} out of range: {src / 'annots.npy'} has {n_views} cameras")

    ims = annots["ims"]
    frames_idx = frame_range(len(ims), start, end, skip)
    picks = [(f, view, "train") for f in frames_idx]
    picks += [(f, v, "test_view") for f in frames_idx[:: max(1, test_every // skip)] for v in test_views]

    mask_root = src / "mask" if (src / "mask").is_dir() else src / "mask_cihp"
    rows, K_list, w_list, paths, splits = [], [], [], [], {}
    for k, (f, v, split) in enumerate(picks):
        paths.append(_frame_files(src, mask_root, ims[f]["ims"][v]))
        rows.append(_smpl_row(smpl, _load_params(src, params_dir, f)))
        K_list.append(Ks[v])
        w_list.append(w2c[v])
        splits.setdefault(split, []).append(k)
    body = SequenceBody(
        "smpl",
        {
            "betas": rows[0]["betas"],
            "gender": np.asarray("neutral"),
            **{key: np.stack([r[key] for r in rows]) for key in ("global_orient", "body_pose", "transl")},
        },
    )
    h, w = read_rgb(paths[0][0]).shape[:2]
    cams = Cameras(w, h, np.stack(K_list), np.stack(w_list))

    def frames():
        for img_path, mask_path in paths:
            m = iio.imread(mask_path)
            yield read_rgb(img_path), ((m[..., 0] if m.ndim == 3 else m) > 0).astype(np.float32)

    return write_imported(out, frames(), len(paths), cams, body, splits, downscale, overwrite, "ZJU-MoCap")


def _cameras(cams_raw: dict, source: Path) -> tuple[np.ndarray, np.ndarray]:
    """(K [V, 3, 3], w2c [V, 4, 4] in metres) of annots.npy's cameras (R, T in millimetres)."""
    Ks, Rs, Ts = (np.asarray(cams_raw[k], np.float64) for k in ("K", "R", "T"))
    n_views = len(Ks)
    if Rs.shape != (n_views, 3, 3) or Ts.reshape(n_views, -1).shape[1] != 3:
        raise ValueError(f"{source}: cams R/T shapes {Rs.shape}/{Ts.shape} do not fit {n_views} views")
    w2c = np.tile(np.eye(4), (n_views, 1, 1))
    w2c[:, :3, :3] = Rs
    w2c[:, :3, 3] = Ts.reshape(n_views, 3) / 1000.0  # millimetres -> metres
    return Ks, w2c


def _frame_files(src: Path, mask_root: Path, rel: str) -> tuple[Path, Path]:
    """(image, mask) of one listed image; a missing one is named."""
    img_path = src / rel
    if not img_path.is_file():
        raise FileNotFoundError(f"{img_path}: image listed in annots.npy is missing")
    mask_path = (mask_root / rel).with_suffix(".png")
    if not mask_path.is_file():
        raise FileNotFoundError(f"{mask_path}: mask for {rel} is missing")
    return img_path, mask_path


def _smpl_row(smpl, p: dict) -> dict:
    """One frame's SMPL parameters in the sequence format: ZJU-MoCap's extra rotation Rh and translation
    Th (about the origin) folded into the global orientation and a translation about the root joint."""
    R_h = _rotvec_to_matrix(p["Rh"])
    j0 = smpl_root_joint(smpl, p["shapes"])
    return {
        "global_orient": _matrix_to_rotvec(R_h @ _rotvec_to_matrix(p["poses"][:3])),
        "body_pose": p["poses"][3:],
        "transl": p["Th"] + R_h @ j0 - j0,
        "betas": p["shapes"],
    }
