"""Filling what the camera never saw: per-face values (decoded surfel colours) of the faces that no
training frame showed, taken from the faces that were shown.

A video filmed from the front leaves the back of the avatar at whatever its untrained features decode
to. :func:`fill_unseen` gives every unseen face a value from the seen ones, in three steps:

1. **Over the surface, within a fill group** (:func:`fill_groups`: head, chest, arms, hands, lower body,
   feet): harmonic interpolation on the face adjacency graph with the seen faces held fixed, so an
   unseen face gets a blend of its nearest seen neighbours, weighted by how close they are along the
   surface. Edges between groups are cut, so the back of the chest learns from the chest, not from the
   trousers or the skin of the arms.
2. **Front to back** for the chest, arms and lower body, where clothing is plausibly the same all
   round: the seen faces of the same group straight through the body along its depth axis (same
   left-right and height position, :func:`front_projection`); mixed with step 1 by ``front_back``. This
   carries the height of a shirt's hem or of shorts from the front to the back.
3. Unseen faces whose group part has no seen face at all (a clip that shows only the upper body: the
   legs) are interpolated across groups from whatever was seen, and a component of the mesh with no
   seen face anywhere (a separate eyeball mesh) takes the mean of its group's seen faces, else of all.

Pure numpy / scipy on small arrays; :mod:`gma.edit.unseen` turns the filled colours into features.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

__all__ = ["FILL_GROUPS", "PROJECTED_GROUPS", "FillResult", "fill_groups", "fill_unseen", "front_projection",
           "harmonic_fill"]

# Fill groups, in the order their masks are applied (a later one wins where region masks overlap).
FILL_GROUPS = ("chest", "lower_body", "arms", "head", "hands", "feet")
# Groups that take the front-to-back prior: garments wrap them. Head (face vs hair), hands and feet
# (palm vs back, sole vs top) are not the same front and back.
PROJECTED_GROUPS = ("chest", "lower_body", "arms")


@dataclass
class FillResult:
    """``values`` [F, D] with the unseen faces filled; ``how`` [F] int8: 0 seen (unchanged), 1 over the
    surface within its group, 2 across groups (its group part had no seen face), 3 by a group or global
    mean (no seen face on its mesh component), -1 left as it was (nothing at all was seen)."""

    values: np.ndarray
    how: np.ndarray

    def summary(self) -> dict:
        n = max(len(self.how), 1)
        names = {"seen": 0, "within_group": 1, "across_groups": 2, "by_mean": 3, "left": -1}
        return {k: round(float((self.how == v).sum()) / n, 4) for k, v in names.items()}


def fill_groups(regions: dict) -> np.ndarray:
    """[F] int group index into :data:`FILL_GROUPS` from a body's coarse regions (``body.regions``: name ->
    [F] bool). The chest is ``upper_body`` without the arms; faces in no region join the chest."""
    def mask(name):
        return np.asarray(regions[name], bool)

    chest = mask("upper_body") & ~mask("arms")
    groups = np.zeros(len(chest), np.int64)  # 0: chest, also for faces no region names
    for i, name in enumerate(FILL_GROUPS):
        m = chest if name == "chest" else mask(name)
        groups[m] = i
    return groups


def _adjacency(pairs: np.ndarray, num_faces: int, keep: np.ndarray | None = None) -> sp.csr_matrix:
    """Symmetric [F, F] 0/1 adjacency from face pairs [P, 2], only the pairs where ``keep`` [P]."""
    if keep is not None:
        pairs = pairs[keep]
    i = np.concatenate([pairs[:, 0], pairs[:, 1]])
    j = np.concatenate([pairs[:, 1], pairs[:, 0]])
    return sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(num_faces, num_faces))


def harmonic_fill(values: np.ndarray, known: np.ndarray, adjacency: sp.csr_matrix) -> tuple[np.ndarray, np.ndarray]:
    """(values [F, D], filled [F] bool): each unknown face connected to a known one gets the harmonic
    interpolation of the known values (every unknown face the mean of its neighbours). Unknown faces in a
    connected component with no known face are left as they were (``filled`` False)."""
    values = np.array(values, np.float64)
    filled = np.zeros(len(known), bool)
    _, comp = connected_components(adjacency, directed=False)
    reachable = np.isin(comp, np.unique(comp[known])) & ~known
    if not reachable.any():
        return values, filled
    u = np.nonzero(reachable)[0]
    k = np.nonzero(known)[0]
    degree = np.asarray(adjacency.sum(1)).ravel()
    a_uu = adjacency[u][:, u]
    # L_uu x_u = A_uk x_k: each unknown face equals the mean of its neighbours. Unknown faces that cannot
    # reach a known one were left out, so every row's component holds a fixed value and L_uu is regular.
    laplacian = (sp.diags(degree[u]) - a_uu).tocsc()
    rhs = adjacency[u][:, k] @ values[k]
    values[u] = splu(laplacian).solve(np.ascontiguousarray(rhs))
    filled[u] = True
    return values, filled


def front_projection(values: np.ndarray, known: np.ndarray, targets: np.ndarray, centers: np.ndarray,
                     depth_axis: int, radius: float, neighbours: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """(values [M, D], found [M] bool) for faces ``targets`` [M]: the inverse-distance mean of the known
    faces nearest to each in the plane across the depth axis (``centers`` [F, 3] rest-pose face centres),
    within ``radius`` (metres); ``found`` False where no known face is that close. The caller restricts
    ``known`` to the target's group."""
    m = len(targets)
    out = np.zeros((m, values.shape[1]))
    found = np.zeros(m, bool)
    src = np.nonzero(known)[0]
    if not len(src) or not m:
        return out, found
    plane = [a for a in range(3) if a != depth_axis]
    tree = cKDTree(centers[src][:, plane])
    dist, idx = tree.query(centers[targets][:, plane], k=min(neighbours, len(src)), distance_upper_bound=radius)
    dist, idx = dist.reshape(m, -1), idx.reshape(m, -1)
    ok = np.isfinite(dist)
    weight = np.where(ok, 1.0 / (dist + 1e-3), 0.0)
    found = ok.any(1)
    safe = np.where(ok, idx, 0)
    total = weight.sum(1, keepdims=True)
    out[found] = ((weight[..., None] * values[src][safe]).sum(1) / np.maximum(total, 1e-12))[found]
    return out, found


def fill_unseen(values, known, pairs, groups, centers, depth_axis: int, front_back: float = 0.5,
                radius: float = 0.03, sources=None) -> FillResult:
    """Fill the values of the faces that are not ``known`` (see the module docstring).

    values [F, D] per-face values (flattened surfel colours); known [F] bool (seen, or otherwise trusted);
    pairs [P, 2] faces sharing an edge (``gma.body.geometry.face_adjacency``); groups [F] int fill groups
    (:func:`fill_groups`); centers [F, 3] rest-pose face centres (m); depth_axis: the body's front-back
    axis (0, 1, 2); front_back in [0, 1]: weight of the front-to-back prior in the groups of
    :data:`PROJECTED_GROUPS`; radius: how far (m) across the depth axis a face looks for its counterpart;
    sources [F] bool (default: ``known``): the known faces values are taken from. A known face that is not
    a source keeps its value but lends it to no one: a face seen only at a grazing angle, whose colour
    the fit blended with the silhouette's background."""
    values = np.asarray(values, np.float64)
    known = np.asarray(known, bool)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    groups = np.asarray(groups, np.int64)
    if not 0.0 <= front_back <= 1.0:
        raise ValueError(f"front_back must be in [0, 1], got {front_back}")
    sources = known if sources is None else np.asarray(sources, bool) & known
    n = len(values)
    how = np.where(known, 0, -1).astype(np.int8)
    if known.all() or not sources.any():
        return FillResult(values.copy(), how)
    within = _adjacency(pairs, n, groups[pairs[:, 0]] == groups[pairs[:, 1]])
    out, filled = harmonic_fill(values, sources, within)
    filled &= ~known
    how[filled] = 1
    _mix_front_projection(out, values, sources, filled, groups, np.asarray(centers, np.float64), depth_axis,
                          front_back, radius)
    rest = ~known & ~filled
    if rest.any():  # whole group parts unseen: across groups, from the sources and what is filled so far
        across, more = harmonic_fill(out, sources | filled, _adjacency(pairs, n))
        more &= rest
        out[more] = across[more]
        how[more] = 2
        rest &= ~more
    for i in np.nonzero(rest)[0]:  # components of the mesh nothing on which was seen
        same = sources & (groups == groups[i])
        out[i] = values[same].mean(0) if same.any() else values[sources].mean(0)
        how[i] = 3
    out[known] = values[known]  # a known face that was no source was solved for in the systems above
    return FillResult(out, how)


def _mix_front_projection(out, values, known, filled, groups, centers, depth_axis, front_back, radius) -> None:
    """Blend the front-to-back prior into ``out`` (in place) for the filled faces of projected groups."""
    if front_back == 0:
        return
    for gi, name in enumerate(FILL_GROUPS):
        if name not in PROJECTED_GROUPS:
            continue
        targets = np.nonzero(filled & (groups == gi))[0]
        proj, found = front_projection(values, known & (groups == gi), targets, centers, depth_axis, radius)
        t = targets[found]
        out[t] = (1.0 - front_back) * out[t] + front_back * proj[found]
