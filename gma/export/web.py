"""An avatar as one self-contained web page that plays it animated (``gma export avatar.gma page.html``).

The page skins the surfels on the GPU rather than storing them posed per frame: it holds the surfels once,
at rest (the avatar's own shape, every bone at identity), each surfel's four strongest bones with weights
blended from its face's vertices by its barycentric position, and per motion frame one rigid transform
per bone. Bones cost a few hundred kB per motion where posed surfels would cost about as much per frame.
The renderer is Spark (three.js, WebGL2), from ``web/`` (npm), bundled by ``npm run build`` into
``web/dist/gma-page.js`` and inlined here, so the page needs no server and no network.

Linear blend skinning of a surfel's centre with its blended weights equals GMA's placement of a surfel
lying on its face, up to the four-bone truncation; Spark blends dual quaternions, which departs from it
only where a surfel's bones turn far apart. Left out: a surfel's stretch with its posed face (GMA scales
it by the face's area) and facial expressions.
"""

from __future__ import annotations

import base64
import gzip
import html
import json
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from gma.avatar.avatar import Avatar
from gma.avatar.model import DecodedAvatar
from gma.avatar.posing import pose_surfels
from gma.body.motions import Motion
from gma.body.placement import rotmat_to_quat
from gma.body.skinning import linear_blend_skinning
from gma.core.atomic import atomic_write_bytes
from gma.core.errors import InputError

__all__ = ["BONES_PER_SURFEL", "PageCamera", "SkinnedSplats", "motion_bones", "motion_bounds", "page_bundle",
           "page_html", "skinned_splats", "write_page"]

BONES_PER_SURFEL = 4  # what Spark's SplatSkinning reads per splat
BUNDLE = Path(__file__).resolve().parents[2] / "web" / "dist" / "gma-page.js"
# How far from its centre Spark draws a splat, in standard deviations. GMA draws a surfel while its
# alpha o·exp(-r²/2) reaches 1/255, out to r = sqrt(2 ln 255) ≈ 3.33 for an opaque one; Spark's default
# (sqrt 8 ≈ 2.83) would trim the soft edge of every silhouette.
MAX_STD_DEV = 3.33


@dataclass
class SkinnedSplats:
    """Surfels at rest, for GPU skinning. N surfels: means [N, 3] (m), quats [N, 4] (x, y, z, w),
    scales [N, 3] (m; the third, normal axis 0, which Spark draws as a 2D Gaussian), opacities [N],
    colors [N, 3] in [0, 1], skin [N, 4] uint16 (Spark's packing: weight·255 in the low byte, bone index
    in the high byte)."""

    means: np.ndarray
    quats: np.ndarray
    scales: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray
    skin: np.ndarray


@dataclass
class PageCamera:
    """The page's starting view: ``eye`` and ``target`` [3] (m, body world frame), ``up`` [3], ``fov_y``
    (degrees, vertical)."""

    eye: tuple[float, float, float]
    target: tuple[float, float, float]
    up: tuple[float, float, float]
    fov_y: float


def page_bundle(bundle: Path | None = None) -> str:
    """The page's JavaScript (Spark, three.js and the player in one ES module), from ``bundle`` (default
    ``web/dist/gma-page.js`` of this checkout)."""
    bundle = bundle or BUNDLE
    if not bundle.is_file():
        raise InputError(f"{bundle}: the web page's JavaScript is not built; it needs node and npm "
                         "(scripts/install.sh, or: cd web && npm ci && npm run build)")
    return bundle.read_text(encoding="utf-8")


def _avatar_params(avatar: Avatar, body) -> dict[str, torch.Tensor]:
    params = {"shape": avatar.shape}
    if "expression" in avatar.info:
        params["expression"] = torch.tensor(avatar.info["expression"], dtype=torch.float32)
    return body.check_params(params)


def surfel_bone_weights(decoded: DecodedAvatar, body, k: int = BONES_PER_SURFEL) -> tuple[np.ndarray, np.ndarray]:
    """Each surfel's ``k`` strongest bones: indices [N, k] int64 and weights [N, k] (sum 1). A surfel's
    weights are its face's vertex weights blended by its barycentric coordinates."""
    b = decoded.binding
    corners = body.faces[b.face_id]  # [N, 3]
    bary = torch.stack([b.uv[:, 0], b.uv[:, 1], 1 - b.uv[:, 0] - b.uv[:, 1]], 1)  # [N, 3]
    dense = torch.zeros(len(b), body.num_bones)
    for c in range(3):
        w = body.skin_weights[corners[:, c]] * bary[:, c:c + 1]  # [N, K]
        dense.scatter_add_(1, body.skin_indices[corners[:, c]].long(), w)
    weights, indices = dense.topk(k, dim=1)
    weights = weights.clamp_min(0)
    weights = weights / weights.sum(1, keepdim=True).clamp_min(1e-12)
    return indices.numpy(), weights.numpy()


def pack_skin(indices: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """[N, 4] uint16 in Spark's layout. Weights are rounded to 1/255 with the rounding error given to the
    strongest bone, so they still sum to 1."""
    if int(indices.max(initial=0)) > 255:
        raise InputError(f"the body has {int(indices.max()) + 1} bones; the web page skins at most 256")
    q = np.rint(weights * 255).astype(np.int64)
    q[:, 0] += 255 - q.sum(1)
    return (np.clip(q, 0, 255) | (indices.astype(np.int64) << 8)).astype(np.uint16)


@torch.no_grad()
def skinned_splats(avatar: Avatar, body, decoded: DecodedAvatar | None = None) -> SkinnedSplats:
    """The avatar's surfels at rest with their bones (see :class:`SkinnedSplats`)."""
    decoded = decoded or avatar.decode()
    identity = torch.eye(4).expand(body.num_bones, 4, 4)
    rest = pose_surfels(decoded, body.faces, body.skin_indices, body.skin_weights,
                        body.rest_vertices(_avatar_params(avatar, body)), identity)
    indices, weights = surfel_bone_weights(decoded, body)
    scales = torch.cat([rest["scales"], torch.zeros_like(rest["scales"][:, :1])], 1)

    def f32(t: torch.Tensor) -> np.ndarray:
        return np.ascontiguousarray(t.detach().cpu().numpy(), np.float32)

    return SkinnedSplats(means=f32(rest["means"]), quats=f32(rest["quats"][:, [1, 2, 3, 0]]), scales=f32(scales),
                         opacities=f32(rest["opacities"].reshape(-1)), colors=f32(rest["colors"].clamp(0, 1)),
                         skin=pack_skin(indices, weights))


def _bone_transforms(avatar: Avatar, body, motion: Motion) -> torch.Tensor:
    """[T, J, 4, 4] rest->posed transforms of every frame, at the avatar's shape."""
    base = _avatar_params(avatar, body)
    return torch.stack([body.bone_transforms(body.check_params({**base, "pose": motion.params(t)["pose"]}))
                        for t in range(len(motion))])


@torch.no_grad()
def motion_bones(avatar: Avatar, body, motion: Motion) -> np.ndarray:
    """[T, J, 7] float32: per frame and bone the rotation (x, y, z, w) and translation (m) of its
    rest->posed transform."""
    transforms = _bone_transforms(avatar, body, motion)
    quats = rotmat_to_quat(transforms[..., :3, :3])[..., [1, 2, 3, 0]]
    return np.ascontiguousarray(torch.cat([quats, transforms[..., :3, 3]], -1).numpy(), np.float32)


@torch.no_grad()
def motion_bounds(avatar: Avatar, body, motion: Motion, samples: int = 8) -> tuple[np.ndarray, np.ndarray]:
    """(min [3], max [3]) of the posed body over ``samples`` frames of ``motion``."""
    rest = body.rest_vertices(_avatar_params(avatar, body))
    frames = sorted({round(i * (len(motion) - 1) / max(samples - 1, 1)) for i in range(samples)})
    base = _avatar_params(avatar, body)
    lo, hi = [], []
    for t in frames:
        transforms = body.bone_transforms(body.check_params({**base, "pose": motion.params(t)["pose"]}))
        v = linear_blend_skinning(rest, body.skin_indices, body.skin_weights, transforms)
        lo.append(v.min(0).values.numpy())
        hi.append(v.max(0).values.numpy())
    return np.min(lo, 0), np.max(hi, 0)


def _pack_arrays(arrays: dict[str, np.ndarray]) -> tuple[bytes, dict[str, dict]]:
    """One little-endian buffer of the arrays (each 4-byte aligned) and where each lies in it."""
    dtypes = {np.dtype(np.float32): "f32", np.dtype(np.uint16): "u16", np.dtype(np.uint8): "u8"}
    chunks, specs, offset = [], {}, 0
    for name, a in arrays.items():
        a = np.ascontiguousarray(a)
        specs[name] = {"offset": offset, "dtype": dtypes[a.dtype], "shape": list(a.shape)}
        raw = a.astype(a.dtype.newbyteorder("<")).tobytes()
        pad = -len(raw) % 4
        chunks.append(raw + b"\0" * pad)
        offset += len(raw) + pad
    return b"".join(chunks), specs


def page_html(title: str, splats: SkinnedSplats, motions: list[tuple[str, Motion, np.ndarray]],
              camera: PageCamera, bundle: str, size: tuple[int, int] | None = None,
              background: tuple[float, float, float] = (1.0, 1.0, 1.0)) -> str:
    """The page's HTML. ``motions``: (name, motion, bones [T, J, 7] from :func:`motion_bones`); ``size``:
    the view's (width, height) in pixels, None to fill the window."""
    arrays = {"means": splats.means, "scales": splats.scales, "quats": splats.quats,
              "opacities": splats.opacities, "colors": splats.colors, "skin": splats.skin}
    arrays.update({f"bones{i}": bones for i, (_, _, bones) in enumerate(motions)})
    blob, specs = _pack_arrays(arrays)
    meta = {
        "numSplats": int(splats.means.shape[0]), "numBones": int(motions[0][2].shape[1]),
        "enable2DGS": True, "maxStdDev": MAX_STD_DEV, "background": list(background),
        "camera": {"eye": list(camera.eye), "target": list(camera.target), "up": list(camera.up),
                   "fovY": camera.fov_y},
        "motions": [{"name": name, "fps": float(m.fps), "frames": len(m), "bones": specs.pop(f"bones{i}")}
                    for i, (name, m, _) in enumerate(motions)],
        "arrays": specs,
    }
    data = base64.b64encode(gzip.compress(blob, compresslevel=9, mtime=0)).decode("ascii")
    template = (Path(__file__).parent / "web_page.html").read_text(encoding="utf-8")
    view_style = f"width:{size[0]}px;height:{size[1]}px;flex:none" if size else "width:100%;flex:1"
    # "</" cannot end a <script> element early inside JSON or base64 once "/" is escaped.
    values = {"title": html.escape(title), "view_style": view_style, "meta": json.dumps(meta).replace("</", "<\\/"),
              "data": data, "bundle": bundle.replace("</script", "<\\/script")}
    return re.sub(r"\{\{(\w+)\}\}", lambda m: values[m.group(1)], template)


def write_page(path: str | Path, page: str) -> Path:
    """Write the page atomically."""
    atomic_write_bytes(path, page.encode("utf-8"))
    return Path(path)
