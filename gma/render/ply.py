"""Reading standard Gaussian-splat PLY files (the INRIA 3DGS layout, also written by 2DGS tools).

Vertex properties: x, y, z; scale_0.. (log scales); rot_0..rot_3 (w, x, y, z, unnormalised); opacity
(a logit); f_dc_0..2 (degree-0 spherical-harmonic colour). A 3D-Gaussian file has three scales: the
smallest is dropped, and the rotation is permuted so that the two kept axes span the surfel plane.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gma.core.atomic import atomic_write_bytes
from gma.core.checks import require_finite
from gma.core.errors import InputError, NonFiniteError
from gma.render.scenes import quat_multiply

SH_C0 = 0.28209479177387814  # degree-0 spherical harmonic constant
# Far above any real scene (the largest public captures have ~10^7), far below what would exhaust memory.
MAX_SPLATS = 100_000_000
REQUIRED = ("x", "y", "z", "rot_0", "rot_1", "rot_2", "rot_3", "opacity", "scale_0", "scale_1")

_PLY_TYPES = {"float": "f4", "float32": "f4", "double": "f8", "float64": "f8", "uchar": "u1", "uint8": "u1",
              "char": "i1", "int8": "i1", "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
              "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4"}


def _vertex_count(word: str, path: Path) -> int:
    """The vertex count of the header, checked against what a file can hold before anything is allocated."""
    try:
        count = int(word)
    except ValueError:
        raise InputError(f"{path}: vertex count {word!r} is not a number") from None
    if count < 1:
        raise InputError(f"{path}: the PLY holds {count} vertices; a splat file needs at least one")
    if count > MAX_SPLATS:
        raise InputError(f"{path}: {count:,} vertices is more than this reader takes ({MAX_SPLATS:,})")
    return count


def _read_header(fh, path: Path) -> tuple[str, int, list[tuple[str, str]]]:
    if fh.readline().strip() != b"ply":
        raise InputError(f"{path}: not a PLY file (missing 'ply' magic)")
    fmt, count, props, in_vertex = None, None, [], False
    while True:
        line = fh.readline()
        if not line:
            raise InputError(f"{path}: PLY header ends without 'end_header'")
        words = line.decode("ascii", "replace").split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        text = " ".join(words)
        if words[0] == "format":
            if len(words) < 2:
                raise InputError(f"{path}: PLY header line {text!r} names no format")
            fmt = words[1]
        elif words[0] == "element":
            if len(words) < 3:
                raise InputError(f"{path}: PLY header line {text!r} needs a name and a count")
            in_vertex = words[1] == "vertex"
            if in_vertex:
                count = _vertex_count(words[2], path)
            elif count is None:
                raise InputError(f"{path}: element '{words[1]}' precedes 'vertex'; not a splat PLY")
        elif words[0] == "property" and in_vertex:
            if len(words) < 3:
                raise InputError(f"{path}: PLY header line {text!r} needs a type and a name")
            if words[1] == "list":
                raise InputError(f"{path}: list properties in the vertex element are not supported")
            if words[1] not in _PLY_TYPES:
                raise InputError(f"{path}: unknown PLY property type {words[1]!r}")
            if any(name == words[2] for name, _ in props):
                raise InputError(f"{path}: vertex property {words[2]!r} is declared twice")
            props.append((words[2], _PLY_TYPES[words[1]]))
        elif words[0] == "end_header":
            break
    if fmt not in ("binary_little_endian", "binary_big_endian", "ascii"):
        raise InputError(f"{path}: unsupported PLY format {fmt!r}")
    if count is None:
        raise InputError(f"{path}: no vertex element")
    return fmt, count, props


def _rotate_to_drop_axis(quats: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """Quaternion whose z axis is the original axis ``drop`` (0, 1 or 2) and whose x, y axes are the
    other two, keeping a right-handed frame (cyclic permutation of the columns)."""
    # Rotations that map the local z axis onto x (drop 0) or y (drop 1), as cyclic axis permutations.
    perm = {0: np.array([0.5, 0.5, 0.5, 0.5]), 1: np.array([0.5, -0.5, -0.5, -0.5])}
    out = quats.copy()
    for axis, q in perm.items():
        sel = drop == axis
        if sel.any():
            out[sel] = quat_multiply(quats[sel], np.broadcast_to(q, (int(sel.sum()), 4)))
    return out


def load_splat_ply(path: str | Path) -> dict[str, np.ndarray]:
    """Read a splat PLY. Returns float32 arrays ``means`` [N, 3], ``quats`` [N, 4] (w, x, y, z),
    ``scales`` [N, 2] (activated), ``opacities`` [N] (activated), ``colors`` [N, 3] (RGB in [0, 1])."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"splat file {path} does not exist")
    with path.open("rb") as fh:
        fmt, count, props = _read_header(fh, path)
        names = [p[0] for p in props]
        missing = [r for r in REQUIRED if r not in names]
        if missing:
            raise InputError(f"{path}: missing splat properties {missing}; expected the INRIA Gaussian layout")
        if fmt == "ascii":
            try:
                data = np.loadtxt(fh, dtype=np.float64, max_rows=count, ndmin=2)
            except ValueError as exc:  # numpy's message names neither the file nor the format
                raise InputError(f"{path}: ASCII vertex data is not {len(props)} numbers per line "
                                 f"({_first_line(exc)})") from None
            if data.shape != (count, len(props)):
                raise InputError(f"{path}: expected {count} vertices of {len(props)} values, got {data.shape}")
            columns = {n: data[:, i] for i, n in enumerate(names)}
        else:
            order = "<" if fmt == "binary_little_endian" else ">"
            dtype = np.dtype([(n, order + t) for n, t in props])
            if path.stat().st_size < dtype.itemsize * count:  # before reading gigabytes of a short file
                raise InputError(f"{path}: file is truncated (the header promises {count:,} vertices of "
                                 f"{dtype.itemsize} bytes, the file has {path.stat().st_size:,} bytes in all)")
            raw = fh.read(dtype.itemsize * count)
            if len(raw) < dtype.itemsize * count:
                raise InputError(f"{path}: file is truncated ({len(raw)} of {dtype.itemsize * count} vertex bytes)")
            arr = np.frombuffer(raw, dtype=dtype, count=count)
            columns = {n: arr[n] for n in names}

    used = [*REQUIRED, "scale_2", "f_dc_0", "f_dc_1", "f_dc_2", "red", "green", "blue"]
    require_finite({f"property {k!r}": columns[k] for k in used if k in columns}, str(path))

    def col(*keys):
        return np.stack([np.asarray(columns[k], np.float64) for k in keys], 1)

    means = col("x", "y", "z")
    quats = col("rot_0", "rot_1", "rot_2", "rot_3")
    log_scales = col(*(k for k in ("scale_0", "scale_1", "scale_2") if k in columns))
    norms = np.linalg.norm(quats, axis=1, keepdims=True)
    quats = np.where(norms > 0, quats / np.maximum(norms, 1e-30), np.array([1.0, 0, 0, 0]))
    if log_scales.shape[1] == 3:
        drop = np.argmin(log_scales, axis=1)
        keep = np.array([[1, 2], [2, 0], [0, 1]])[drop]  # the two other axes in cyclic order
        log_scales = np.take_along_axis(log_scales, keep, axis=1)
        quats = _rotate_to_drop_axis(quats, drop)
    if all(f"f_dc_{i}" in columns for i in range(3)):
        colors = np.clip(0.5 + SH_C0 * col("f_dc_0", "f_dc_1", "f_dc_2"), 0.0, 1.0)
    elif all(k in columns for k in ("red", "green", "blue")):
        colors = col("red", "green", "blue") / 255.0
    else:
        colors = np.full((count, 3), 0.7)
    # Finite properties can still overflow once activated (a log scale of 1000): checked below, in one
    # line, instead of numpy's overflow warnings.
    with np.errstate(over="ignore"):
        opacities = 1.0 / (1.0 + np.exp(-np.asarray(columns["opacity"], np.float64)))
        out = {"means": means, "quats": quats, "scales": np.exp(log_scales), "opacities": opacities, "colors": colors}
        out = {k: np.ascontiguousarray(v, np.float32) for k, v in out.items()}
    require_finite({f"{k} (activated)": v for k, v in out.items()}, f"{path}: values too large", InputError)
    return out


def _quat_normals(quats: np.ndarray) -> np.ndarray:
    """[N, 3] third column of the rotation of unit-or-not quaternions [N, 4] (w, x, y, z): a surfel's normal."""
    q = np.asarray(quats, np.float64)
    q = q / np.maximum(np.linalg.norm(q, axis=1, keepdims=True), 1e-30)
    w, x, y, z = q.T
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], 1)


def save_splat_ply(path: str | Path, means, quats, scales, opacities, colors, thickness: float | None = None,
                   sh_degree: int = 0) -> None:
    """Write surfels in the INRIA layout, atomically: x y z, nx ny nz (the surfel normal), f_dc_0..2,
    [f_rest_0..44 all zero when ``sh_degree`` is 3], opacity (logit), scale_* (log), rot_0..3 (w, x, y, z).

    means [N, 3] (m), quats [N, 4], scales [N, 2] (m, activated), opacities [N] in (0, 1), colors [N, 3] RGB.
    ``thickness`` None writes two scales (the 2DGS layout); a number (m) writes a third, flat-axis scale of
    that size, so that 3DGS tools that expect three scales show each surfel as a thin disc (capped at half
    the surfel's smaller scale, so that the flat axis stays the smallest and readers that drop the
    smallest axis, as :func:`load_splat_ply` does, drop this one).
    """
    if sh_degree not in (0, 3):
        raise ValueError(f"sh_degree must be 0 or 3, got {sh_degree}")
    path = Path(path)
    n = len(means)
    scales = np.asarray(scales, np.float64)
    if thickness is not None:
        flat = np.minimum(float(thickness), 0.5 * scales.min(1, initial=np.inf)) if n else np.zeros(0)
        scales = np.concatenate([scales, flat[:, None]], 1)
    rest = 45 if sh_degree == 3 else 0
    props = (["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2"] + [f"f_rest_{i}" for i in range(rest)]
             + ["opacity"] + [f"scale_{i}" for i in range(scales.shape[1])] + [f"rot_{i}" for i in range(4)])
    o = np.clip(np.asarray(opacities, np.float64), 1e-6, 1 - 1e-6)
    data = np.concatenate([
        np.asarray(means, np.float64), _quat_normals(quats), (np.asarray(colors, np.float64)[:, :3] - 0.5) / SH_C0,
        np.zeros((n, rest)), np.log(o / (1 - o))[:, None], np.log(np.maximum(scales, 1e-12)),
        np.asarray(quats, np.float64)], 1).astype("<f4")
    require_finite({"the splat data": data}, f"{path}: not written", NonFiniteError)
    prop_lines = "".join(f"property float {p}\n" for p in props)
    header = f"ply\nformat binary_little_endian 1.0\nelement vertex {n}\n{prop_lines}end_header\n"
    atomic_write_bytes(path, header.encode("ascii") + data.tobytes())


def _first_line(exc: Exception) -> str:
    return str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
