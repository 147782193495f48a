"""Filling what the camera never saw: per-face values (decoded surfel colours) of the faces that no
training frame showed, taken from the faces that were shown.

A video filmed from the front leaves the back of the avatar at whatever its untrained features decode
to. :func:`fill_unseen` gives every unseen face a value from the seen ones, in these steps:

1. **From the mirror face**: an unseen face whose left-right mirror was seen takes its mirror's value
   (when the caller passes ``mirror_of``).
2. **Over the surface, within a fill group** (:func:`fill_groups`: head, chest, arms, hands, lower body,
   feet): harmonic interpolation on the face adjacency graph with the seen faces held fixed, so an
   unseen face gets a blend of its nearest seen neighbours, weighted by how close they are along the
   surface. Edges between groups are cut, so the back of the chest learns from the chest, not from the
   trousers or the skin of the arms.
3. **Front to back**, per group by :data:`FRONT_BACK`: the seen faces of the same group straight through
   the body along its depth axis (same left-right and height position, :func:`front_projection`), mixed
   with step 2. Trousers and sleeves are the same all round (weight 1); a shirt's front (a print, a zip),
   a palm and the toe of a shoe less often match their back (0.5).
4. **Over the head**: the back and sides of the head take the colour of the seen crown (head faces whose
   normal points up: the hair, or a bald scalp), straight down along the up axis, not the skin of the
   face, which surface propagation would spread round the head. The face itself (normals pointing
   forward) is left to steps 1-2.
5. Unseen faces whose group part has no seen face at all (a clip that shows only the upper body: the
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

__all__ = ["FILL_GROUPS", "FRONT_BACK", "FillResult", "Orientation", "fill_groups", "fill_unseen",
           "front_projection", "harmonic_fill"]

# Fill groups, in the order their masks are applied (a later one wins where region masks overlap).
FILL_GROUPS = ("chest", "lower_body", "arms", "head", "hands", "feet")
# Weight of the front-to-back prior per group (0 or absent: surface propagation alone). The head is not
# in it: its front is a face, its back hair (the crown prior, step 4, does the head).
FRONT_BACK = {"chest": 0.5, "lower_body": 1.0, "arms": 1.0, "hands": 0.5, "feet": 0.5}
# How far (m) across the depth axis a face looks for its counterpart, and among how many it averages: an
# average, not the nearest face, since a print on the front does not sit at the same place on the back.
FRONT_BACK_RADIUS = 0.05
FRONT_BACK_NEIGHBOURS = 8
# The crown: head faces whose normal's cosine with the up axis is above this; the face (normal's cosine
# with the forward axis above CROWN_FACE) takes nothing from it.
CROWN_UP = 0.5
CROWN_FACE = 0.5
CROWN_NEIGHBOURS = 8
_HOW = {"seen": 0, "within_group": 1, "across_groups": 2, "by_mean": 3, "mirror": 4, "left": -1}


@dataclass
class FillResult:
    """``values`` [F, D] with the unseen faces filled; ``how`` [F] int8: 0 seen (unchanged), 1 over the
    surface within its group, 2 across groups (its group part had no seen face), 3 by a group or global
    mean (no seen face on its mesh component), 4 from its mirror face, -1 left as it was (nothing at all
    was seen)."""

    values: np.ndarray
    how: np.ndarray

    def summary(self) -> dict:
        n = max(len(self.how), 1)
        return {k: round(float((self.how == v).sum()) / n, 4) for k, v in _HOW.items()}


@dataclass(frozen=True)
class Orientation:
    """The body's axes in its rest frame, for the crown prior: per-face unit normals [F, 3], and the unit
    up and forward vectors [3]."""

    normals: np.ndarray
    up: np.ndarray
    forward: np.ndarray


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


def fill_unseen(values, known, pairs, groups, centers, depth_axis: int, front_back=None,
                radius: float = FRONT_BACK_RADIUS, mirror_of=None, orientation: Orientation | None = None
                ) -> FillResult:
    """Fill the values of the faces that are not ``known`` (see the module docstring).

    values [F, D] per-face values (flattened surfel colours); known [F] bool (seen well: the faces values
    are taken from); pairs [P, 2] faces sharing an edge (``gma.body.geometry.face_adjacency``); groups [F]
    int fill groups (:func:`fill_groups`); centers [F, 3] rest-pose face centres (m); depth_axis: the
    body's front-back axis (0, 1, 2); front_back: weights of the front-to-back prior per group name
    (default :data:`FRONT_BACK`), or one weight in [0, 1] for every group of :data:`FRONT_BACK`; radius: how
    far (m) across the depth axis a face looks for its counterpart; mirror_of [F] int (optional): each
    face's left-right mirror face (step 1); orientation (optional): the body's axes, for the crown prior of
    the head (step 4)."""
    values = np.asarray(values, np.float64)
    known = np.asarray(known, bool)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    groups = np.asarray(groups, np.int64)
    weights = _front_back_weights(front_back)
    n = len(values)
    how = np.where(known, 0, -1).astype(np.int8)
    if known.all() or not known.any():
        return FillResult(values.copy(), how)
    values, known = _from_mirror(values, known, mirror_of, how)
    within = _adjacency(pairs, n, groups[pairs[:, 0]] == groups[pairs[:, 1]])
    out, filled = harmonic_fill(values, known, within)
    how[filled] = 1
    centers = np.asarray(centers, np.float64)
    _mix_front_projection(out, values, known, filled, groups, centers, depth_axis, weights, radius)
    if orientation is not None:
        _mix_crown(out, values, known, filled, groups, centers, orientation)
    rest = ~known & ~filled
    if rest.any():  # whole group parts unseen: across groups, from the known faces and what is filled so far
        across, more = harmonic_fill(out, known | filled, _adjacency(pairs, n))
        more &= rest
        out[more] = across[more]
        how[more] = 2
        rest &= ~more
    for i in np.nonzero(rest)[0]:  # components of the mesh nothing on which was seen
        same = known & (groups == groups[i])
        out[i] = values[same].mean(0) if same.any() else values[known].mean(0)
        how[i] = 3
    return FillResult(out, how)


def _front_back_weights(front_back) -> dict[str, float]:
    """Per-group weights from ``fill_unseen``'s ``front_back`` (None, one number or a mapping)."""
    if front_back is None:
        return dict(FRONT_BACK)
    if isinstance(front_back, dict):
        weights = {k: float(v) for k, v in front_back.items()}
        unknown = sorted(set(weights) - set(FILL_GROUPS))
        if unknown:
            raise ValueError(f"front_back: unknown fill groups {unknown}; known: {', '.join(FILL_GROUPS)}")
    else:
        weights = dict.fromkeys(FRONT_BACK, float(front_back))
    bad = {k: v for k, v in weights.items() if not 0.0 <= v <= 1.0}
    if bad:
        raise ValueError(f"front_back weights must be in [0, 1], got {bad}")
    return weights


def _from_mirror(values, known, mirror_of, how):
    """Step 1: unknown faces whose mirror face is known take its value and count as known from then on
    (``how`` 4, in place). Returns (values, known), new arrays."""
    if mirror_of is None:
        return values, known
    mirror_of = np.asarray(mirror_of, np.int64)
    take = ~known & known[mirror_of]
    values = values.copy()
    values[take] = values[mirror_of[take]]
    how[take] = _HOW["mirror"]
    return values, known | take


def _mix_front_projection(out, values, known, filled, groups, centers, depth_axis, weights, radius) -> None:
    """Blend the front-to-back prior into ``out`` (in place) for the filled faces of weighted groups."""
    for gi, name in enumerate(FILL_GROUPS):
        weight = weights.get(name, 0.0)
        if weight == 0:
            continue
        targets = np.nonzero(filled & (groups == gi))[0]
        proj, found = front_projection(values, known & (groups == gi), targets, centers, depth_axis, radius,
                                       FRONT_BACK_NEIGHBOURS)
        t = targets[found]
        out[t] = (1.0 - weight) * out[t] + weight * proj[found]


def _mix_crown(out, values, known, filled, groups, centers, orientation: Orientation) -> None:
    """Step 4 (in place): the filled faces of the head, except the face, take the mean of the nearest
    seen crown faces across the up axis."""
    head = groups == FILL_GROUPS.index("head")
    normals = np.asarray(orientation.normals, np.float64)
    crown = known & head & (normals @ orientation.up > CROWN_UP)
    targets = np.nonzero(filled & head & (normals @ orientation.forward <= CROWN_FACE))[0]
    if not crown.any() or not len(targets):
        return
    up_axis = int(np.argmax(np.abs(orientation.up)))
    proj, found = front_projection(values, crown, targets, centers, up_axis, np.inf, CROWN_NEIGHBOURS)
    out[targets[found]] = proj[found]
