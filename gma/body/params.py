"""Per-frame body parameters (``body.npz`` of a sequence): loading, validation, saving, and locating
the user's SMPL / SMPL-X model files.

Models and their arrays (T = number of frames; all float unless noted; angles are axis-angle in
radians, lengths in metres):

- ``anny`` (default, free): ``pose`` [T, 104, 4, 4] Anny ``local-ref`` bone transforms of the default
  rig (bone 0 = root, carries global rotation and translation); ``phenotype`` [6] in [0, 1] (gender,
  age, muscle, weight, height, proportions); optional ``facial_actions`` [T, 52] in [0, 1]; optional
  ``fps`` (scalar, frames per second: motion files from ``gma import motion`` carry it).
- ``smplx``: ``betas`` [B], ``global_orient`` [T, 3], ``body_pose`` [T, 63], ``jaw_pose``,
  ``leye_pose``, ``reye_pose`` [T, 3], ``left_hand_pose``, ``right_hand_pose`` [T, 45],
  ``expression`` [T, E], ``transl`` [T, 3], ``gender`` (string).
- ``smpl`` (what PeopleSnapshot and ZJU-MoCap ship): ``betas`` [B], ``global_orient`` [T, 3],
  ``body_pose`` [T, 69], ``transl`` [T, 3], ``gender`` (string). SMPL semantics: the global rotation
  turns the body about its root joint, then ``transl`` is added.

The file is read with ``allow_pickle=False``: a sequence from a stranger must not run code.
"""

from __future__ import annotations

import os
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gma.core.atomic import atomic_write_npz
from gma.core.errors import InputError

__all__ = [
    "ANNY_BONES",
    "BODY_MODELS",
    "SequenceBody",
    "find_model_file",
    "load_body",
    "load_smpl_model_arrays",
    "require_body_model",
    "save_body",
]

BODY_MODELS = ("anny", "smplx", "smpl")
ANNY_BONES = 104
ANNY_PHENOTYPE = 6
ANNY_FACIAL_ACTIONS = 52

# name -> trailing shape of the per-frame array (None = any length, e.g. expression size E)
_PER_FRAME = {
    "anny": {"pose": (ANNY_BONES, 4, 4), "facial_actions": (ANNY_FACIAL_ACTIONS,)},
    "smplx": {
        "global_orient": (3,), "body_pose": (63,), "jaw_pose": (3,), "leye_pose": (3,),
        "reye_pose": (3,), "left_hand_pose": (45,), "right_hand_pose": (45,), "expression": (None,),
        "transl": (3,),
    },
    "smpl": {"global_orient": (3,), "body_pose": (69,), "transl": (3,)},
}
_REQUIRED = {
    "anny": ("pose", "phenotype"),
    "smplx": ("betas", "global_orient", "body_pose", "transl", "gender"),
    "smpl": ("betas", "global_orient", "body_pose", "transl", "gender"),
}
# Optional SMPL-X arrays default to zeros of this size when absent.
_SMPLX_DEFAULTS = {"jaw_pose": 3, "leye_pose": 3, "reye_pose": 3, "left_hand_pose": 45,
                   "right_hand_pose": 45, "expression": 10}
GENDERS = ("neutral", "male", "female")

MODEL_URL = {"smplx": "https://smpl-x.is.tue.mpg.de", "smpl": "https://smpl.is.tue.mpg.de"}
MODEL_ENV = {"smplx": "GMA_SMPLX_DIR", "smpl": "GMA_SMPL_DIR"}


@dataclass
class SequenceBody:
    """Body model name plus its arrays (see the module docstring for names and shapes)."""

    model: str
    arrays: dict[str, np.ndarray]

    @property
    def num_frames(self) -> int:
        key = "pose" if self.model == "anny" else "global_orient"
        return int(self.arrays[key].shape[0])

    @property
    def gender(self) -> str | None:
        g = self.arrays.get("gender")
        return None if g is None else str(g)

    def frame(self, i: int) -> dict[str, np.ndarray]:
        """Arrays for frame ``i``: per-frame arrays indexed, per-sequence ones (shape) as they are."""
        per_frame = _PER_FRAME[self.model]
        return {k: (v[i] if k in per_frame else v) for k, v in self.arrays.items()}

    def subset(self, indices) -> SequenceBody:
        """The same person over frames ``indices`` (in that order)."""
        idx = np.asarray(indices, dtype=np.int64)
        per_frame = _PER_FRAME[self.model]
        arrays = {k: (v[idx] if k in per_frame else v) for k, v in self.arrays.items()}
        return SequenceBody(self.model, arrays)


def _shape_str(shape) -> str:
    return "[" + ", ".join("T" if s == -1 else ("*" if s is None else str(s)) for s in shape) + "]"


def validate_body(body: SequenceBody, source: str, num_frames: int | None = None) -> None:
    """Raise ``ValueError`` naming ``source`` on any unknown model, missing array, wrong shape,
    disagreeing frame count or non-finite value."""
    if body.model not in BODY_MODELS:
        raise ValueError(f"{source}: unknown body model {body.model!r}; expected one of {BODY_MODELS}")
    a = body.arrays
    for key in _REQUIRED[body.model]:
        if key not in a:
            raise ValueError(f"{source}: body model {body.model!r} needs array {key!r}, which is missing")
    per_frame = _PER_FRAME[body.model]
    t = num_frames if num_frames is not None else body.num_frames
    for key, value in a.items():
        if key == "gender":
            if str(value) not in GENDERS:
                raise ValueError(f"{source}: gender {str(value)!r} is not one of {GENDERS}")
            continue
        if not np.issubdtype(value.dtype, np.number):
            raise ValueError(f"{source}: array {key!r} has non-numeric dtype {value.dtype}")
        if key in per_frame:
            want = (-1, *per_frame[key])
            ok = value.ndim == len(want) and all(
                w in (-1, None) or w == s for w, s in zip(want, value.shape, strict=True)
            )
            if not ok:
                got = list(value.shape)
                raise ValueError(f"{source}: {key!r} has shape {got}, expected {_shape_str(want)}")
            if value.shape[0] != t:
                raise ValueError(f"{source}: {key!r} has {value.shape[0]} frames but the sequence has {t}")
        elif key in ("betas",):
            if value.ndim != 1:
                raise ValueError(f"{source}: 'betas' has shape {list(value.shape)}, expected [B]")
        elif key == "fps":
            if value.ndim != 0 or not float(value) > 0:
                raise ValueError(f"{source}: 'fps' must be one positive number, got {value.tolist()}")
        elif key == "phenotype":
            if value.shape != (ANNY_PHENOTYPE,):
                raise ValueError(f"{source}: 'phenotype' has shape {list(value.shape)}, expected [6]")
        else:
            raise ValueError(f"{source}: unexpected array {key!r} for body model {body.model!r}")
        if not np.all(np.isfinite(value)):
            bad = np.argwhere(~np.isfinite(value))[0].tolist()
            raise ValueError(f"{source}: {key!r} holds a non-finite value (first at index {bad})")
    if body.model == "anny":
        if np.any((a["phenotype"] < 0) | (a["phenotype"] > 1)):
            raise ValueError(f"{source}: 'phenotype' must lie in [0, 1], got {a['phenotype'].tolist()}")
        if "facial_actions" in a and np.any((a["facial_actions"] < 0) | (a["facial_actions"] > 1)):
            raise ValueError(f"{source}: 'facial_actions' must lie in [0, 1]")
        last = a["pose"][..., 3, :]
        if not np.allclose(last, [0.0, 0.0, 0.0, 1.0], atol=1e-5):
            raise ValueError(f"{source}: 'pose' holds 4x4 matrices whose last row is not [0, 0, 0, 1]")
        rot = a["pose"][..., :3, :3].astype(np.float64)
        err = np.abs(rot @ np.swapaxes(rot, -1, -2) - np.eye(3)).max(initial=0.0)
        if err > 1e-3:
            raise ValueError(f"{source}: 'pose' rotation blocks are not orthonormal (error {err:.2g})")


def load_body(path: str | os.PathLike, num_frames: int | None = None) -> SequenceBody:
    """Read and validate ``body.npz``; ``num_frames`` (when given) must match its frame count.

    Optional SMPL-X arrays (face, eyes, hands, expression) are filled with zeros when absent, since
    several datasets leave them out.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: body parameter file not found")
    with path.open("rb") as fh:
        magic = fh.read(4)
    if magic != b"PK\x03\x04":  # np.load would try to unpickle anything that is not a zip or .npy
        raise InputError(f"{path}: not an .npz file (an .npz is a zip archive of numpy arrays)")
    try:
        with np.load(path, allow_pickle=False) as data:
            arrays = {k: data[k] for k in data.files}
    except ValueError:  # an array stored as pickled Python objects
        raise InputError(f"{path}: holds pickled Python objects, which GMA never loads (a file from a stranger "
                         "could run code); store plain numeric arrays and a string 'model'") from None
    except Exception as exc:  # zipfile.BadZipFile, OSError, EOFError ... from a truncated file
        raise InputError(f"{path}: not a readable .npz file ({exc})") from None
    if "model" not in arrays:
        raise ValueError(f"{path}: no 'model' entry (expected one of {BODY_MODELS})")
    model = str(arrays.pop("model"))
    if "gender" in arrays:
        arrays["gender"] = np.asarray(str(arrays["gender"]))
    body = SequenceBody(model, arrays)
    if model == "smplx" and "global_orient" in arrays:
        t = arrays["global_orient"].shape[0]
        for key, size in _SMPLX_DEFAULTS.items():
            arrays.setdefault(key, np.zeros((t, size), np.float32))
    validate_body(body, str(path), num_frames)
    return body


def save_body(path: str | os.PathLike, body: SequenceBody) -> None:
    """Validate, then atomically write ``body.npz`` (float arrays stored as float32)."""
    validate_body(body, str(path))
    out = {"model": np.asarray(body.model)}
    for k, v in body.arrays.items():
        v = np.asarray(v)
        out[k] = np.asarray(str(v)) if k == "gender" else v.astype(np.float32)
    atomic_write_npz(path, **out)


# -- user-supplied SMPL / SMPL-X model files -----------------------------------------------------------


def _candidates(model: str, gender: str, root: Path) -> list[Path]:
    g = gender.upper()
    names = [f"{model.upper()}_{g}.npz", f"{model.upper()}_{g}.pkl"]
    if model == "smpl":
        short = {"neutral": "neutral", "male": "m", "female": "f"}[gender]
        names += [f"basicmodel_{short}_lbs_10_207_0_v1.1.0.pkl",
                  f"basicModel_{short}_lbs_10_207_0_v1.0.0.pkl"]
    return [d / n for d in (root, root / model) for n in names]


def find_model_file(model: str, gender: str = "neutral", model_dir: str | os.PathLike | None = None) -> Path:
    """The user's SMPL (``model='smpl'``) or SMPL-X (``'smplx'``) model file for ``gender``.

    Looks in ``model_dir``, else ``$GMA_SMPL_DIR`` / ``$GMA_SMPLX_DIR``, for ``SMPLX_NEUTRAL.npz`` (or
    ``.pkl``, other genders, the official SMPL ``basicmodel_*`` names), directly or in a ``smpl``/``smplx``
    subfolder. Raises ``FileNotFoundError`` that says where to get the files when none is found.
    """
    if model not in MODEL_ENV:
        raise ValueError(f"no model files are needed for body model {model!r}")
    if gender not in GENDERS:
        raise ValueError(f"gender {gender!r} is not one of {GENDERS}")
    env = MODEL_ENV[model]
    where = model_dir or os.environ.get(env)
    hint = (f"The {model.upper()} model files are not shipped with GMA (their licence forbids it): "
            f"register at {MODEL_URL[model]}, download the model, and pass --{model}-dir DIR "
            f"or set {env}=DIR.")
    if not where:
        raise FileNotFoundError(f"{model.upper()} model files needed but no directory given. {hint}")
    root = Path(where).expanduser()
    cands = _candidates(model, gender, root)
    for c in cands:
        if c.is_file():
            return c
    raise FileNotFoundError(
        f"{model.upper()} model file for gender {gender!r} not found in {root} (looked for "
        f"{', '.join(str(c) for c in cands[:2])}, ...). {hint}"
    )


def require_body_model(body: SequenceBody, source: str, model_dir: str | os.PathLike | None = None) -> None:
    """Raise a clear error when the body model ``body`` needs is not installed: the ``anny`` package
    for Anny, the user's model files for SMPL / SMPL-X."""
    if body.model == "anny":
        import importlib.util

        if importlib.util.find_spec("anny") is None:
            raise FileNotFoundError(f"{source}: needs the 'anny' package (pip install anny)")
        return
    try:
        find_model_file(body.model, body.gender or "neutral", model_dir)
    except FileNotFoundError as exc:
        raise FileNotFoundError(f"{source}: {exc}") from exc


class RestrictedUnpickler(pickle.Unpickler):
    """Unpickler for files the user downloaded from the SMPL website / datasets: only numpy arrays,
    scipy sparse matrices and plain builtins may be built, so a hostile file cannot run code."""

    _ALLOWED = {
        ("numpy", "ndarray"), ("numpy", "dtype"), ("numpy.core.multiarray", "_reconstruct"),
        ("numpy._core.multiarray", "_reconstruct"), ("numpy.core.multiarray", "scalar"),
        ("numpy._core.multiarray", "scalar"), ("builtins", "slice"), ("collections", "OrderedDict"),
        ("scipy.sparse.csc", "csc_matrix"), ("scipy.sparse._csc", "csc_matrix"),
        ("scipy.sparse.csr", "csr_matrix"), ("scipy.sparse._csr", "csr_matrix"),
    }

    def find_class(self, module, name):
        if (module, name) in self._ALLOWED:
            if module.startswith("scipy"):
                import scipy.sparse

                return getattr(scipy.sparse, name)
            return super().find_class(module, name)
        if module.startswith("chumpy"):
            return _ChumpyArray
        raise pickle.UnpicklingError(f"refusing to load {module}.{name} (only numpy/builtins are allowed)")


class _ChumpyArray:
    """Stands in for the chumpy arrays inside the official SMPL ``.pkl``: keeps the wrapped values."""

    def __setstate__(self, state):
        self.x = np.asarray(state.get("x")) if isinstance(state, dict) and "x" in state else None

    def __array__(self, dtype=None, copy=None):
        if self.x is None:
            raise ValueError("a chumpy expression in this .pkl cannot be read safely; convert it to .npz")
        return self.x if dtype is None else self.x.astype(dtype)


def restricted_pickle_load(path: str | os.PathLike):
    """Load a third-party ``.pkl`` (SMPL model files, X-Humans parameters) with the allow-list above.
    Never used for GMA's own files, which are npz / json / safetensors."""
    with open(path, "rb") as f:
        try:
            return RestrictedUnpickler(f, encoding="latin1").load()
        except (pickle.UnpicklingError, EOFError, AttributeError, ImportError) as exc:
            raise ValueError(f"{path}: cannot be read safely as a pickle ({exc})") from exc


def load_smpl_model_arrays(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """``v_template`` [V, 3], ``shapedirs`` [V, 3, B], ``J_regressor`` [J, V] (dense) from a SMPL or
    SMPL-X model file (``.npz`` read without pickle; ``.pkl`` through the restricted unpickler)."""
    path = Path(path)
    if path.suffix == ".npz":
        with np.load(path, allow_pickle=False) as d:
            raw = {k: d[k] for k in ("v_template", "shapedirs", "J_regressor") if k in d.files}
    else:
        raw = restricted_pickle_load(path)
        if not isinstance(raw, dict):
            raise ValueError(f"{path}: expected a dict of model arrays")
    out = {}
    for key in ("v_template", "shapedirs", "J_regressor"):
        if key not in raw:
            raise ValueError(f"{path}: model file has no {key!r}")
        value = raw[key]
        if hasattr(value, "toarray"):
            value = value.toarray()
        out[key] = np.asarray(value, dtype=np.float64)
    v = out["v_template"].shape[0]
    sd, jr = out["shapedirs"], out["J_regressor"]
    if out["v_template"].shape != (v, 3) or sd.shape[:2] != (v, 3) or jr.ndim != 2 or jr.shape[1] != v:
        raise ValueError(f"{path}: model arrays have inconsistent shapes")
    return out


def smpl_root_joint(model_arrays: dict[str, np.ndarray], betas: np.ndarray) -> np.ndarray:
    """Rest-pose root (pelvis) joint [3] in metres for shape ``betas`` [B] (extra betas ignored)."""
    shapedirs = model_arrays["shapedirs"]
    b = min(len(betas), shapedirs.shape[2])
    verts = model_arrays["v_template"] + shapedirs[:, :, :b] @ np.asarray(betas[:b], np.float64)
    return model_arrays["J_regressor"][0] @ verts
