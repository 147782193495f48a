"""Retargeting skeletal motion from other rigs (SMPL / SMPL-X, BVH) onto Anny's 104-bone rig.

Source rigs of this kind have world-aligned joint frames at rest, and a joint's local rotation turns its
subtree about world-aligned axes in the parent's posed frame: a joint's world rotation from rest is
``G_s = G_parent · R_s``. Anny's ``local-ref`` deltas are nearly that convention, but relative to its
reference bone orientations U rather than its rest orientations R: the skinning rotation of bone c is
``G_c = G_p · A_p^T · D_c · A_c`` with ``A = U R^T`` (a few degrees from I for some bones, which is why
identity deltas give Anny's canonical pose rather than exactly its rest pose). What also differs is
(a) the axes (Anny: Z up, faces −Y, left +X), (b) the rest pose (Anny rests in an A-pose with bent
forearms, SMPL-X and most BVH files in a T-pose) and (c) the bone set. So, per Anny bone c:

    G_c = C_world · G_s · C_rest^T · Q_c      for a mapped bone with source joint s,
    G_c = G_parent                            for an unmapped one (twist bones, toes, spine04, …),
    D_c = A_p · G_p^T · G_c · A_c^T           (the root: D_0 = U_0 · G_0 · R_0 · U_0^T)

``C_rest`` / ``C_world`` change the axes of the source's rest skeleton / world into Anny's, and ``Q_c`` is
the smallest rotation that turns Anny's rest bone direction onto the source's (both in Anny axes), so
that posed limbs point where the source's do.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from gma.core.errors import InputError

__all__ = ["JOINT_MAP", "SMPLX_JOINTS", "RetargetRig", "axes_from_skeleton", "reference_pose", "rest_heads",
           "rotation_between", "smplx_rig"]

# fmt: off
# The joint mapping, one row per mapped Anny bone:
#   (Anny bone, SMPL / SMPL-X joint, BVH joint names (CMU first, then common alternatives),
#    Anny bone whose head sets this bone's rest direction (None: no direction is matched))
_BODY_ROWS = (
    ("root",         "pelvis",         ("Hips", "hip", "Hip", "Pelvis", "pelvis", "Root"),             None),
    ("upperleg01.L", "left_hip",       ("LeftUpLeg", "LeftHip", "lThigh", "LeftUpperLeg", "LHip"),      "lowerleg01.L"),
    ("lowerleg01.L", "left_knee",      ("LeftLeg", "LeftKnee", "lShin", "LeftLowerLeg", "LKnee"),       "foot.L"),
    ("foot.L",       "left_ankle",     ("LeftFoot", "LeftAnkle", "lFoot", "LAnkle"),                    None),
    ("upperleg01.R", "right_hip",      ("RightUpLeg", "RightHip", "rThigh", "RightUpperLeg", "RHip"),   "lowerleg01.R"),
    ("lowerleg01.R", "right_knee",     ("RightLeg", "RightKnee", "rShin", "RightLowerLeg", "RKnee"),    "foot.R"),
    ("foot.R",       "right_ankle",    ("RightFoot", "RightAnkle", "rFoot", "RAnkle"),                  None),
    ("spine05",      "spine1",         ("LowerBack", "Spine", "spine", "abdomen", "Spine0"),            None),
    ("spine03",      "spine2",         ("Spine1", "spine1", "chest", "Chest"),                          None),
    ("spine01",      "spine3",         ("Spine2", "spine2", "Chest2", "UpperChest"),                    None),
    ("neck01",       "neck",           ("Neck", "neck"),                                                None),
    ("head",         "head",           ("Head", "head"),                                                None),
    ("clavicle.L",   "left_collar",    ("LeftShoulder", "LeftCollar", "lCollar", "LeftClavicle"),       None),
    ("upperarm01.L", "left_shoulder",  ("LeftArm", "LeftUpArm", "lShldr", "LeftUpperArm", "LShoulder"), "lowerarm01.L"),
    ("lowerarm01.L", "left_elbow",     ("LeftForeArm", "LeftLowArm", "lForeArm", "LeftLowerArm", "LElbow"), "wrist.L"),
    ("wrist.L",      "left_wrist",     ("LeftHand", "LeftWrist", "lHand", "LWrist"),                    "finger3-1.L"),
    ("clavicle.R",   "right_collar",   ("RightShoulder", "RightCollar", "rCollar", "RightClavicle"),    None),
    ("upperarm01.R", "right_shoulder", ("RightArm", "RightUpArm", "rShldr", "RightUpperArm", "RShoulder"),
                                                                                                    "lowerarm01.R"),
    ("lowerarm01.R", "right_elbow",    ("RightForeArm", "RightLowArm", "rForeArm", "RightLowerArm", "RElbow"),
                                                                                                    "wrist.R"),
    ("wrist.R",      "right_wrist",    ("RightHand", "RightWrist", "rHand", "RWrist"),                  "finger3-1.R"),
)
# Fingers (SMPL-X hand joints; Anny finger1 = thumb … finger5 = little finger), joints 1-3 of each.
_FINGERS = (("thumb", 1), ("index", 2), ("middle", 3), ("ring", 4), ("pinky", 5))
_FINGER_BVH = {"thumb": "Thumb", "index": "Index", "middle": "Middle", "ring": "Ring", "pinky": "Pinky"}
_FINGER_ROWS = tuple(
    (f"finger{k}-{j}.{s}", f"{side}_{name}{j}", (f"{Side}Hand{_FINGER_BVH[name]}{j}",),
     f"finger{k}-{j + 1}.{s}" if j < 3 else None)
    for side, Side, s in (("left", "Left", "L"), ("right", "Right", "R"))
    for name, k in _FINGERS for j in (1, 2, 3)
)
JOINT_MAP = _BODY_ROWS + _FINGER_ROWS

# SMPL-X joints 0..54 (SMPL+H uses the first 22 and the hand joints 25..54 as its 22..51).
SMPLX_JOINTS = (
    "pelvis", "left_hip", "right_hip", "spine1", "left_knee", "right_knee", "spine2", "left_ankle", "right_ankle",
    "spine3", "left_foot", "right_foot", "neck", "left_collar", "right_collar", "head", "left_shoulder",
    "right_shoulder", "left_elbow", "right_elbow", "left_wrist", "right_wrist", "jaw", "left_eye", "right_eye",
    *(f"{side}_{f}{j}" for side in ("left", "right") for f in ("index", "middle", "pinky", "ring", "thumb")
      for j in (1, 2, 3)),
)
SMPLX_PARENTS = (
    -1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 15, 15, 15,
    20, 25, 26, 20, 28, 29, 20, 31, 32, 20, 34, 35, 20, 37, 38,
    21, 40, 41, 21, 43, 44, 21, 46, 47, 21, 49, 50, 21, 52, 53,
)
# fmt: on

# SMPL / SMPL-X rest (T-pose) bone directions in the model's own axes (Y up, +X the body's left, faces
# +Z), for the bones whose rest direction differs from Anny's: arms and fingers held out sideways.
# Everything else (legs, spine, head) stands upright in both rigs and is taken as already matching.
_SMPL_TPOSE_DIRECTIONS = {
    **{j: (1.0, 0.0, 0.0) for j in ("left_shoulder", "left_elbow", "left_wrist")},
    **{j: (-1.0, 0.0, 0.0) for j in ("right_shoulder", "right_elbow", "right_wrist")},
    **{f"{side}_{f}{j}": (sign, 0.0, 0.0) for side, sign in (("left", 1.0), ("right", -1.0))
       for f, _ in _FINGERS for j in (1, 2)},
}


def rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[..., 3, 3] the smallest rotation turning direction ``a`` [..., 3] onto ``b`` [..., 3]."""
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    v = np.cross(a, b)
    c = np.sum(a * b, -1)[..., None, None]
    k = np.zeros(v.shape[:-1] + (3, 3))
    k[..., 0, 1], k[..., 0, 2], k[..., 1, 2] = -v[..., 2], v[..., 1], -v[..., 0]
    k = k - np.swapaxes(k, -1, -2)
    # Rodrigues with sin·k/|v| = k and (1 − cos)/sin² = 1 / (1 + cos); opposite directions are not
    # expected between rigs (a bone pointing backwards) and are clamped rather than special-cased.
    return np.eye(3) + k + (k @ k) / np.maximum(1.0 + c, 1e-6)


def axes_from_skeleton(left: np.ndarray, up: np.ndarray) -> np.ndarray:
    """[3, 3] rotation from a source's axes into Anny's, given the source's body-left and up directions
    (Anny: left +X, up +Z, forward −Y; forward = left × up in both)."""
    up = up / np.linalg.norm(up)
    left = left - up * (left @ up)
    left = left / np.linalg.norm(left)
    fwd = np.cross(left, up)
    src = np.stack([left, up, fwd], 1)  # columns: the source's left, up, forward
    anny = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]]).T  # columns: Anny's left, up, fwd
    return anny @ src.T


SMPL_AXES = axes_from_skeleton(np.array([1.0, 0.0, 0.0]), np.array([0.0, 1.0, 0.0]))


def _rest_bone_poses(body, shape: torch.Tensor | None = None) -> torch.Tensor:
    p = body.canonical_params(shape)
    with torch.no_grad():
        return body._rest_model(p["shape"][None], p["expression"][None])["rest_bone_poses"][0].double()


def rest_heads(body, shape: torch.Tensor | None = None) -> np.ndarray:
    """[J, 3] Anny's rest bone heads (m) at phenotype ``shape`` (default: the default phenotype)."""
    return _rest_bone_poses(body, shape)[:, :3, 3].numpy()


def rest_rotations(body, shape: torch.Tensor | None = None) -> np.ndarray:
    """[J, 3, 3] Anny's rest bone orientations at phenotype ``shape`` (default: the default phenotype)."""
    return _rest_bone_poses(body, shape)[:, :3, :3].numpy()


@dataclass
class RetargetRig:
    """A source rig matched to Anny: ``anny_idx`` [M] mapped Anny bones, ``src_idx`` [M] their source
    joints, ``Q`` [M, 3, 3] rest alignments (Anny axes), ``c_rest`` / ``c_world`` [3, 3], and Anny's
    ``parents`` [J] (parents before children), ``A`` [J, 3, 3] = U R^T, root ``U0`` / ``R0`` [3, 3]."""

    anny_idx: np.ndarray
    src_idx: np.ndarray
    Q: np.ndarray
    c_rest: np.ndarray
    c_world: np.ndarray
    parents: np.ndarray
    A: np.ndarray
    U0: np.ndarray
    R0: np.ndarray

    @staticmethod
    def build(body, src_index: dict[str, int], src_rest_dir, c_rest: np.ndarray,
              c_world: np.ndarray | None = None, names: str = "smplx") -> RetargetRig:
        """Match ``body`` (Anny) to a source rig. ``src_index`` maps the source's joint names to indices;
        ``names`` is which column of :data:`JOINT_MAP` names them ("smplx" or "bvh");
        ``src_rest_dir(src_joint, src_child_joint)`` returns the source's rest bone direction (source
        axes) or None where it is taken to match Anny's."""
        heads = rest_heads(body)
        bones = body.bone_names
        rows = []
        for anny, smplx, bvh, child in JOINT_MAP:
            candidates = (smplx,) if names == "smplx" else bvh
            src = next((n for n in candidates if n in src_index), None)
            if src is not None and anny in bones:
                rows.append((anny, src, child, candidates))
        row_src = {anny: src for anny, src, _, _ in rows}
        anny_idx = np.array([bones.index(r[0]) for r in rows], np.int64)
        Q = np.tile(np.eye(3), (len(rows), 1, 1))
        for m, (anny, src, child, _) in enumerate(rows):
            if child is not None and child in row_src:
                d_src = src_rest_dir(src, row_src[child])
                if d_src is not None:
                    d_anny = heads[bones.index(child)] - heads[bones.index(anny)]
                    Q[m] = rotation_between(d_anny, c_rest @ np.asarray(d_src, np.float64))
        R = rest_rotations(body)
        U = body.anny_model.reference_bone_orientations.double().numpy()
        return RetargetRig(anny_idx, np.array([src_index[r[1]] for r in rows], np.int64), Q, c_rest,
                           c_rest if c_world is None else c_world, np.asarray(body.bone_parents, np.int64),
                           U @ np.swapaxes(R, -1, -2), U[0], R[0])

    def local_deltas(self, src_global: np.ndarray) -> np.ndarray:
        """Anny ``local-ref`` rotations [T, J, 3, 3] from the source joints' world rotations
        ``src_global`` [T, S, 3, 3] (each from its rest, source axes)."""
        t, nb = src_global.shape[0], len(self.parents)
        target = np.full((t, nb, 3, 3), np.nan)
        target[:, self.anny_idx] = self.c_world @ src_global[:, self.src_idx] @ self.c_rest.T @ self.Q
        G = np.empty((t, nb, 3, 3))
        D = np.empty((t, nb, 3, 3))
        for j, p in enumerate(self.parents):  # parents come first in Anny's bone order
            if not np.isnan(target[0, j, 0, 0]):
                G[:, j] = target[:, j]
            else:
                G[:, j] = np.eye(3) if p < 0 else G[:, p]
            if p < 0:
                D[:, j] = self.U0 @ G[:, j] @ self.R0 @ self.U0.T
            else:
                D[:, j] = self.A[p] @ np.swapaxes(G[:, p], -1, -2) @ G[:, j] @ self.A[j].T
        return D


def smplx_rig(body, joints: tuple[str, ...] = SMPLX_JOINTS, c_world: np.ndarray | None = None) -> RetargetRig:
    """The retargeting rig for SMPL / SMPL-X joint rotations (T-pose rest, Y-up model axes)."""

    def rest_dir(joint: str, _child: str):
        return _SMPL_TPOSE_DIRECTIONS.get(joint)

    return RetargetRig.build(body, {n: i for i, n in enumerate(joints)}, rest_dir, SMPL_AXES, c_world, "smplx")


def reference_pose(body, name: str) -> dict[str, torch.Tensor]:
    """Body params of a named pose: ``canonical`` (Anny's rest: an A-pose with slightly bent forearms),
    ``tpose`` (arms straight out sideways, fingers flat) or ``apose`` (the T-pose with both arms lowered
    45°)."""
    pose = body.canonical_pose()
    if name == "canonical":
        return {"pose": pose}
    if name not in ("tpose", "apose"):
        raise InputError(f"unknown pose {name!r}; expected canonical, tpose or apose")
    if body.name != "anny":
        raise InputError(f"--pose {name} is for avatars on the Anny rig, not {body.name!r} (use canonical)")
    rig = smplx_rig(body)
    g = np.tile(np.eye(3), (1, len(SMPLX_JOINTS), 1, 1))
    if name == "apose":  # the shoulders lower the arms 45° about the forward axis (SMPL +Z)
        c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
        down = {"left": np.array([[c, s, 0], [-s, c, 0], [0, 0, 1]]),
                "right": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])}
        for i, n in enumerate(SMPLX_JOINTS):
            side = n.split("_")[0]
            if side in down and (n.endswith(("shoulder", "elbow", "wrist")) or any(f in n for f, _ in _FINGERS)):
                g[0, i] = down[side]
    out = pose.clone()
    out[:, :3, :3] = torch.from_numpy(rig.local_deltas(g)[0]).float()
    return {"pose": out}
