"""Triangle-mesh geometry in torch, differentiable w.r.t. vertex positions where training needs it.

All functions take ``vertices`` [..., V, 3] (float) and ``faces`` [F, 3] (int64, counter-clockwise seen
from outside). Leading batch dimensions are allowed for the per-vertex/per-face quantities. Normalising
uses ``safe_normalize`` (divide by max(|x|, EPS)) so degenerate faces give zero vectors, never NaN — and
the WGSL kernels use the same rule, so both paths agree on them.
"""

from __future__ import annotations

import torch

__all__ = [
    "EPS",
    "cotangent_laplacian",
    "edge_lengths",
    "face_adjacency",
    "face_areas",
    "face_centers",
    "face_frames",
    "face_normals",
    "frame_from",
    "mesh_edges",
    "mirror_faces",
    "morph_vertices",
    "safe_normalize",
    "uniform_laplacian",
    "vertex_adjacency",
    "vertex_normals",
]

EPS = 1e-12


def safe_normalize(x: torch.Tensor, dim: int = -1) -> torch.Tensor:
    return x / x.norm(dim=dim, keepdim=True).clamp_min(EPS)


def _corners(vertices: torch.Tensor, faces: torch.Tensor) -> tuple[torch.Tensor, ...]:
    return vertices[..., faces[:, 0], :], vertices[..., faces[:, 1], :], vertices[..., faces[:, 2], :]


def face_centers(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[..., F, 3] centroids."""
    a, b, c = _corners(vertices, faces)
    return (a + b + c) / 3.0


def face_normals(vertices: torch.Tensor, faces: torch.Tensor, normalize: bool = True) -> torch.Tensor:
    """[..., F, 3] face normals; unnormalised ones have length 2·area."""
    a, b, c = _corners(vertices, faces)
    n = torch.linalg.cross(b - a, c - a, dim=-1)
    return safe_normalize(n) if normalize else n


def face_areas(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[..., F] triangle areas (m²)."""
    return 0.5 * face_normals(vertices, faces, normalize=False).norm(dim=-1)


def face_frames(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[..., F, 3, 3] per-face rotation whose columns are (tangent, bitangent, normal).

    tangent = direction of the first edge (v0 → v1), normal = face normal, bitangent = n × t; a proper
    rotation (det +1) for every non-degenerate face. This is the surfel frame convention of
    ``gma.body.placement`` and ``shaders/wgsl/body/place.wgsl``.
    """
    a, b, c = _corners(vertices, faces)
    return frame_from(b - a, safe_normalize(torch.linalg.cross(b - a, c - a, dim=-1)))


def frame_from(edge: torch.Tensor, normal: torch.Tensor) -> torch.Tensor:
    """[..., 3, 3] the face frame of :func:`face_frames` from a face's first edge (v0 → v1) and its unit
    normal, for callers that have both already."""
    t = safe_normalize(edge)
    return torch.stack([t, torch.linalg.cross(normal, t, dim=-1), normal], dim=-1)


def vertex_normals(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """[..., V, 3] area-weighted vertex normals (sum of the unnormalised normals of incident faces)."""
    fn = face_normals(vertices, faces, normalize=False)  # [..., F, 3], length 2·area
    out = torch.zeros_like(vertices)
    index = faces.reshape(-1)  # [3F]: each face's normal goes to its three corners
    contrib = fn.unsqueeze(-2).expand(*fn.shape[:-1], 3, 3).reshape(*fn.shape[:-2], -1, 3)
    out = out.index_add(-2, index, contrib)
    return safe_normalize(out)


def morph_vertices(vertices: torch.Tensor, faces: torch.Tensor, offsets: torch.Tensor) -> torch.Tensor:
    """The mesh layer of the paper: vertices moved by per-vertex scalar ``offsets`` [..., V] (metres)
    along their area-weighted normals → [..., V, 3]. Apply to the rest vertices, before skinning."""
    return vertices + offsets.unsqueeze(-1) * vertex_normals(vertices, faces)


def mesh_edges(faces: torch.Tensor) -> torch.Tensor:
    """[E, 2] unique undirected edges (smaller index first), sorted."""
    e = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 0)
    e = torch.sort(e, dim=1).values
    return torch.unique(e, dim=0)


def edge_lengths(
    vertices: torch.Tensor, faces: torch.Tensor, edges: torch.Tensor | None = None
) -> torch.Tensor:
    """[..., E] lengths of ``edges`` (default: ``mesh_edges(faces)``)."""
    if edges is None:
        edges = mesh_edges(faces)
    return (vertices[..., edges[:, 0], :] - vertices[..., edges[:, 1], :]).norm(dim=-1)


def vertex_adjacency(faces: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """Sparse COO [V, V] 0/1 adjacency (symmetric, no self loops)."""
    e = mesh_edges(faces)
    idx = torch.cat([e, e.flip(1)], 0).T
    vals = torch.ones(idx.shape[1], dtype=torch.float32)
    return torch.sparse_coo_tensor(idx, vals, (num_vertices, num_vertices), check_invariants=False).coalesce()


def face_adjacency(faces: torch.Tensor) -> torch.Tensor:
    """[P, 2] pairs of faces sharing an edge (each pair once, smaller face index first).

    Edges shared by more than two faces (non-manifold) give every pair among them.
    """
    f = faces.shape[0]
    e = torch.cat([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]], 0)
    e = torch.sort(e, dim=1).values
    face_of = torch.arange(f, device=faces.device).repeat(3)
    _, edge_id = torch.unique(e, dim=0, return_inverse=True)
    order = torch.argsort(edge_id, stable=True)
    edge_sorted, face_sorted = edge_id[order], face_of[order]
    # Consecutive entries with the same edge id are faces sharing that edge (manifold: exactly 2).
    pairs = []
    for shift in (1, 2, 3):  # up to 4 faces per edge covers every mesh we load
        same = edge_sorted[shift:] == edge_sorted[:-shift] if edge_sorted.numel() > shift else None
        if same is None or not bool(same.any()):
            break
        pairs.append(torch.stack([face_sorted[:-shift][same], face_sorted[shift:][same]], 1))
    if not pairs:
        return torch.zeros(0, 2, dtype=torch.long, device=faces.device)
    p = torch.sort(torch.cat(pairs, 0), dim=1).values
    return torch.unique(p, dim=0)


def uniform_laplacian(faces: torch.Tensor, num_vertices: int) -> torch.Tensor:
    """Sparse [V, V] graph Laplacian L = I − D⁻¹A (rows of a vertex with neighbours sum to 0).

    ``(L @ x)`` is each vertex minus the mean of its neighbours: the umbrella operator used for
    smoothness losses. Isolated vertices get a zero row.
    """
    adj = vertex_adjacency(faces, num_vertices)
    idx, val = adj.indices(), adj.values()
    deg = torch.zeros(num_vertices).index_add(0, idx[0], val)
    off = -val / deg[idx[0]]
    diag_idx = torch.arange(num_vertices)
    diag = (deg > 0).float()
    indices = torch.cat([idx, torch.stack([diag_idx, diag_idx])], 1)
    values = torch.cat([off, diag])
    shape = (num_vertices, num_vertices)
    return torch.sparse_coo_tensor(indices, values, shape, check_invariants=False).coalesce()


def cotangent_laplacian(vertices: torch.Tensor, faces: torch.Tensor) -> torch.Tensor:
    """Sparse [V, V] cotangent Laplacian L = D − W with W_ij = ½(cot α_ij + cot β_ij) for vertices
    [V, 3] (unbatched). Positive semi-definite; ``L @ x`` is the (unnormalised) mean-curvature vector
    for x = vertices. Differentiable w.r.t. ``vertices`` through the values."""
    if vertices.dim() != 2:
        raise ValueError("cotangent_laplacian takes unbatched vertices [V, 3]")
    v = vertices.shape[0]
    a, b, c = _corners(vertices, faces)
    # The cotangent of the angle at each corner, opposite the edge between the other two corners.
    def cot(p, q, r):  # angle at p between (q - p) and (r - p)
        u, w = q - p, r - p
        return (u * w).sum(-1) / torch.linalg.cross(u, w, dim=-1).norm(dim=-1).clamp_min(EPS)

    cot_a, cot_b, cot_c = cot(a, b, c), cot(b, c, a), cot(c, a, b)
    i = torch.cat([faces[:, 1], faces[:, 2], faces[:, 0]])
    j = torch.cat([faces[:, 2], faces[:, 0], faces[:, 1]])
    w = 0.5 * torch.cat([cot_a, cot_b, cot_c])
    rows = torch.cat([i, j, i, j])
    cols = torch.cat([j, i, i, j])
    vals = torch.cat([-w, -w, w, w])
    return torch.sparse_coo_tensor(torch.stack([rows, cols]), vals, (v, v), check_invariants=False).coalesce()


def mirror_faces(vertices: torch.Tensor, faces: torch.Tensor, tolerance: float = 1e-3) -> torch.Tensor:
    """[F] index of each face's mirror image across the plane x = 0 of a rest mesh ``vertices`` [V, 3]:
    the face whose centre is nearest the face's centre with x negated. Raises ValueError when the mesh is
    not left-right symmetric (some mirrored centre more than ``tolerance`` metres from every face centre,
    or two faces claiming one mirror)."""
    from scipy.spatial import cKDTree

    centers = face_centers(vertices.detach().double(), faces).numpy()
    dist, index = cKDTree(centers).query(centers * [-1.0, 1.0, 1.0])
    worst = float(dist.max())
    if worst > tolerance:
        raise ValueError(f"the body mesh is not left-right symmetric about x = 0 (a mirrored face centre lies "
                         f"{worst * 1000:.1f} mm from the nearest face): mirrored edits and the symmetry prior "
                         "need one that is")
    index = torch.from_numpy(index).long()
    if not torch.equal(index[index], torch.arange(len(index))):
        raise ValueError("the body mesh's faces do not pair up with mirror images: mirrored edits and the "
                         "symmetry prior need a symmetric mesh")
    return index
