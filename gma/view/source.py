"""What the viewer draws: a *surfel source* owns the renderer's input buffers and, for body-bound
sources, the posed mesh the overlays and the selection use.

Two sources exist, and one adapter for fitted avatars:

- :class:`StaticSource`: fixed surfels (a splat PLY); no body, no mesh, no posing.
- :class:`BodySource`: surfels bound to a body mesh (placeholder surfels now, a fitted avatar's decoded
  surfels later). Per frame only the [J, 4, 4] bone transforms go to the GPU, where ``GpuPoser`` skins
  the mesh and places the surfels straight into :class:`SurfelBuffers` (no readback). Shape and
  expression changes re-upload the rest vertices ([V, 3], a few hundred kB) once per change.
- ``.gma`` avatars: :func:`avatar_source` builds a :class:`BodySource` from the avatar's decoded
  binding, colours, opacities and per-vertex morph offsets, at the avatar's own body shape. It lives on
  the view side because the view layer sits above the avatar layer (gma.avatar knows nothing of views).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import numpy as np
import torch

from gma.avatar import Avatar
from gma.body import load_body
from gma.body.gpu_posing import GpuPoser
from gma.body.placement import SurfelBinding, uniform_surfels
from gma.body.skinning import linear_blend_skinning
from gma.gpu import GpuContext
from gma.render.ply import load_splat_ply
from gma.render.surfels import SurfelBuffers

__all__ = ["BodySource", "MeshLayer", "StaticSource", "SurfelSource", "avatar_source", "load_source",
           "placeholder_surfels"]

# Distinct, readable colours for the fine part labels of placeholder surfels (cycled when more labels).
_PALETTE = np.array([
    [0.85, 0.68, 0.58], [0.93, 0.78, 0.66], [0.80, 0.55, 0.45], [0.76, 0.52, 0.42], [0.30, 0.30, 0.35],
    [0.95, 0.95, 0.95], [0.30, 0.30, 0.35], [0.95, 0.95, 0.95], [0.20, 0.10, 0.10], [0.20, 0.10, 0.10],
    [0.60, 0.20, 0.25], [0.35, 0.35, 0.55], [0.35, 0.35, 0.55], [0.75, 0.30, 0.35],
], np.float32)


@dataclass
class MeshLayer:
    """GPU buffers of the posed body mesh, read by the overlay pipelines (never copied back).

    ``positions``: packed f32 [V, 3] posed vertices (m); ``faces``: packed u32 [F, 3]."""

    positions: object  # wgpu.GPUBuffer
    faces: object  # wgpu.GPUBuffer
    num_vertices: int
    num_faces: int


class SurfelSource(Protocol):
    """The viewer's interface to anything it can draw."""

    name: str
    surfels: SurfelBuffers
    up_axis: str  # "y" or "z": the world axis shown upwards by default

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(min [3], max [3]) of the current geometry in world units, for framing the camera."""

    def encode_update(self, encoder) -> bool:
        """Record this frame's GPU work (posing) into ``encoder``; True when something was recorded."""

    @property
    def version(self) -> object:
        """A value that changes whenever the surfels to draw may have changed."""

    @property
    def mesh(self) -> MeshLayer | None:
        """The posed mesh for overlays and selection, or None (a plain splat cloud)."""


class StaticSource:
    """Fixed surfels uploaded once (e.g. a splat PLY)."""

    up_axis = "y"
    mesh = None
    body = None

    def __init__(self, ctx: GpuContext, arrays: dict[str, np.ndarray], name: str = "surfels",
                 up_axis: str = "y"):
        self.name, self.up_axis = name, up_axis
        self.means = np.asarray(arrays["means"], np.float32)
        colors = np.asarray(arrays["colors"], np.float32)[:, :3]
        self.surfels = SurfelBuffers.from_arrays(ctx, self.means, arrays["quats"], arrays["scales"],
                                                 arrays["opacities"], colors)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        if len(self.means) == 0:
            return np.full(3, -1.0, np.float32), np.ones(3, np.float32)
        # Percentiles, not min/max: splat files often hold a few far-away floaters.
        return np.percentile(self.means, 1, axis=0), np.percentile(self.means, 99, axis=0)

    def encode_update(self, encoder) -> bool:
        return False

    version = (0, 0)  # fixed surfels never change


def placeholder_surfels(body, count: int, seed: int = 0):
    """(binding, colours [N, 3], opacities [N]) for ``count`` surfels spread over the body's faces,
    coloured by fine part label: something to look at (and benchmark) before a fitted avatar exists."""
    nf = body.num_faces
    per_face = max(1, math.ceil(count / nf))
    b = uniform_surfels(nf, per_face, scale=0.55 / math.sqrt(per_face) * 1.3, seed=seed)
    if len(b) > count:
        keep = torch.randperm(len(b), generator=torch.Generator().manual_seed(seed))[:count].sort().values
        b = SurfelBinding(b.face_id[keep], b.uv[keep], b.offset[keep], b.scale[keep], b.quat[keep])
    labels = body.face_labels[b.face_id].numpy()
    rng = np.random.default_rng(seed)
    colors = _PALETTE[labels % len(_PALETTE)] * rng.uniform(0.92, 1.0, (len(b), 1)).astype(np.float32)
    return b, colors.astype(np.float32), np.full(len(b), 0.95, np.float32)


class BodySource:
    """Surfels bound to a body mesh, posed on the GPU every time the pose changes.

    ``binding`` (SurfelBinding of N surfels), ``colors`` [N, 3] in [0, 1], ``opacities`` [N];
    ``vertex_offsets`` [V, 3] (m) are a fitted avatar's morph added to the body's rest vertices.
    """

    def __init__(self, ctx: GpuContext, body, binding, colors, opacities, name: str = "body",
                 vertex_offsets=None):
        self.ctx, self.body, self.name = ctx, body, name
        self.up_axis = body.up_axis
        self.binding = binding
        self.poser = GpuPoser(ctx, body.faces, body.skin_indices, body.skin_weights)
        self.poser.set_surfels(binding)
        n = len(binding)
        self.surfels = SurfelBuffers.allocate(ctx, n, 3)
        ctx.write(self.surfels.colors, np.asarray(colors, np.float32))
        ctx.write(self.surfels.opacities, np.asarray(opacities, np.float32))
        self.vertex_offsets = None if vertex_offsets is None else torch.as_tensor(vertex_offsets).float()
        self.params = body.canonical_params()
        self._rest_key: bytes | None = None
        self._dirty = True
        self._expr_basis = getattr(body, "expression_basis", lambda: None)()
        self._neutral_rest: tuple[bytes, torch.Tensor] | None = None
        self._rest: torch.Tensor | None = None
        self.pose_version = 0  # bumped whenever the posed mesh may have changed (edit tools cache views on it)
        self.color_version = 0  # bumped by colour-only writes (an edit's preview)
        self.set_params(self.params)

    @staticmethod
    def placeholder(ctx: GpuContext, body, count: int = 50_000, seed: int = 0) -> BodySource:
        binding, colors, opacities = placeholder_surfels(body, count, seed)
        return BodySource(ctx, body, binding, colors, opacities, name=f"body:{body.name}")

    # -- parameters -----------------------------------------------------------------------------------
    def set_params(self, params: dict) -> None:
        """Set (some of) the body parameters; the GPU work is recorded by the next :meth:`encode_update`.

        Shape or expression changes recompute the rest vertices on the CPU (expressions through the
        linear expression basis when the body has one: a [52] x [52, V, 3] product, not a model run)."""
        with torch.no_grad():
            params = self.body.check_params({**self.params, **params})
            shape, expr = params["shape"], params["expression"]
            key = shape.numpy().tobytes() + b"|" + expr.numpy().tobytes()
            if key != self._rest_key:
                self._rest = self._rest_vertices(params)
                self.poser.set_rest_vertices(self._rest)
                self._rest_key = key
            self._transforms = self.body.bone_transforms(params)
            self.poser.set_bone_transforms(self._transforms)
        self.params = params
        self._dirty = True
        self.pose_version += 1

    def set_expression(self, expression) -> None:
        """Fast path for playback: new expression weights, pose and shape unchanged (facial actions move
        no bone, so only the rest vertices are recomputed and uploaded)."""
        expr = torch.as_tensor(expression, dtype=torch.float32)
        params = {**self.params, "expression": expr}
        key = params["shape"].numpy().tobytes() + b"|" + expr.numpy().tobytes()
        if key != self._rest_key:
            with torch.no_grad():
                self._rest = self._rest_vertices(params)
            self.poser.set_rest_vertices(self._rest)
            self._rest_key = key
            self._dirty = True
            self.pose_version += 1
        self.params = params

    def set_bone_transforms(self, transforms) -> None:
        """Fast path for playback: upload precomputed [J, 4, 4] transforms (shape must not change)."""
        self._transforms = torch.as_tensor(transforms, dtype=torch.float32)
        self.poser.set_bone_transforms(self._transforms)
        self._dirty = True
        self.pose_version += 1

    def update_rows(self, rows, colors=None, mesh: bool = False, max_runs: int = 256, gap: int = 16) -> int:
        """Rewrite the surfel rows [R] an edit changed, from ``self.binding`` (edited in place by the edit
        library) and ``colors`` [N, 3] (the full colour table, read at ``rows`` only). Only the touched rows
        travel: one write per run of rows (runs less than ``gap`` rows apart are merged: a few untouched
        rows cost less than another queue write; the span from the first to the last row when more than
        ``max_runs`` runs remain). With ``mesh`` the rest vertices (which include
        ``vertex_offsets``, edited in place too) are recomputed and uploaded. Pipelines and buffers are kept;
        the next frame re-poses. Returns the bytes written."""
        from gma.body.placement import pack_surfel_local

        rows = np.unique(np.asarray(rows, np.int64).reshape(-1))
        written = 0
        if len(rows):
            breaks = np.nonzero(np.diff(rows) > gap)[0] + 1
            starts, ends = np.r_[rows[0], rows[breaks]], np.r_[rows[breaks - 1], rows[-1]] + 1
            if len(starts) > max_runs:
                starts, ends = starts[:1], ends[-1:]
            b = self.binding
            for lo, hi in zip(starts.tolist(), ends.tolist()):
                span = SurfelBinding(b.face_id[lo:hi], b.uv[lo:hi], b.offset[lo:hi], b.scale[lo:hi], b.quat[lo:hi])
                packed = pack_surfel_local(span)
                self.ctx.write(self.poser.surfels_buf, packed, lo * packed.dtype.itemsize)
                written += packed.nbytes
                if colors is not None:
                    col = np.ascontiguousarray(np.asarray(colors[lo:hi], np.float32))
                    self.ctx.write(self.surfels.colors, col, lo * 12)
                    written += col.nbytes
        if mesh:
            self._rest_key = None  # vertex_offsets changed: recompute the rest vertices on the next set
            self.set_params({})
            written += self._rest.numel() * 4
        self._dirty = True
        self.pose_version += 1
        return written

    def write_colors(self, rows, colors) -> None:
        """Overwrite the colours of surfel ``rows`` [R] with ``colors`` [R, 3] on the GPU only (an edit's
        preview; :meth:`update_rows` writes the decoded result later). One write per contiguous run."""
        rows = np.asarray(rows, np.int64).reshape(-1)
        colors = np.asarray(colors, np.float32).reshape(-1, 3)
        if not len(rows):
            return
        order = np.argsort(rows, kind="stable")
        rows, colors = rows[order], colors[order]
        breaks = np.nonzero(np.diff(rows) != 1)[0] + 1
        for seg_rows, seg_cols in zip(np.split(rows, breaks), np.split(colors, breaks)):
            self.ctx.write(self.surfels.colors, np.ascontiguousarray(seg_cols), int(seg_rows[0]) * 12)
        self.color_version += 1

    @property
    def version(self) -> tuple[int, int]:
        """Changes whenever the surfels to draw may have changed (the viewer reuses a frame while it does not)."""
        return self.pose_version, self.color_version

    def _rest_vertices(self, params: dict) -> torch.Tensor:
        shape, expr = params["shape"], params["expression"]
        if self._expr_basis is not None:
            neutral_key = shape.numpy().tobytes()
            if self._neutral_rest is None or self._neutral_rest[0] != neutral_key:
                neutral = self.body.rest_vertices({"shape": shape, "expression": torch.zeros_like(expr)})
                self._neutral_rest = (neutral_key, neutral)
            rest = self._neutral_rest[1] + torch.einsum("k,kvc->vc", expr, self._expr_basis)
        else:
            rest = self.body.rest_vertices(params)
        if self.vertex_offsets is not None:
            rest = rest + self.vertex_offsets
        return rest

    def posed_vertices(self) -> np.ndarray:
        """[V, 3] posed vertices of the current parameters, computed in torch on the CPU (for a user
        action such as a selection; the frame loop never calls this)."""
        with torch.no_grad():
            v = linear_blend_skinning(self._rest, self.body.skin_indices, self.body.skin_weights, self._transforms)
        return v.numpy()

    # -- SurfelSource -------------------------------------------------------------------------------
    @property
    def mesh(self) -> MeshLayer:
        p = self.poser
        return MeshLayer(p.posed_buf, p.faces_buf, p.num_vertices, p.num_faces)

    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        rest = self._rest.numpy()
        return rest.min(0), rest.max(0)

    def encode_update(self, encoder) -> bool:
        if not self._dirty:
            return False
        self.poser.encode(encoder, self.surfels.means, self.surfels.quats, self.surfels.scales)
        self._dirty = False
        return True


def load_source(ctx: GpuContext, spec: str, surfels: int = 50_000) -> SurfelSource:
    """Open ``spec``: ``body:anny`` / ``body:smplx`` (the body with ``surfels`` placeholder surfels),
    a splat ``.ply``, or a fitted avatar ``.gma``. Raises FileNotFoundError / ValueError naming the file."""
    if spec.startswith("body:"):
        return BodySource.placeholder(ctx, load_body(spec.split(":", 1)[1]), surfels)
    path = Path(spec)
    if not path.exists():
        raise FileNotFoundError(f"{path} does not exist (expected a .gma avatar, a splat .ply, or body:anny)")
    suffix = path.suffix.lower()
    if suffix == ".ply":
        return StaticSource(ctx, load_splat_ply(path), name=path.name)
    if suffix == ".gma":
        return avatar_source(ctx, path)
    raise ValueError(f"{path}: unknown source format {suffix!r}; expected .gma, .ply or body:anny")


def avatar_source(ctx: GpuContext, path) -> BodySource:
    """A :class:`BodySource` showing the avatar file at ``path`` (what ``gma view avatar.gma`` opens), posed
    at the avatar's own body shape. ``source.avatar`` and ``source.decoded`` keep the features and the
    decoded surfels for the edit tools."""
    avatar = Avatar.load(path)
    body = load_body(avatar.body_name)
    dec = avatar.decode()
    src = BodySource(ctx, body, dec.binding, dec.colors.numpy(), dec.opacities.numpy(), name=Path(path).name,
                     vertex_offsets=dec.vertex_offsets)
    src.set_params({"shape": avatar.shape})
    if "expression" in avatar.info:  # the avatar's own default expression (written by the edit tools)
        src.set_params({"expression": torch.tensor(avatar.info["expression"], dtype=torch.float32)})
    src.avatar, src.decoded, src.path = avatar, dec, Path(path)
    return src
