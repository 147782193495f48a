"""Clothing for the synthetic person: which surface is shirt, trousers, shoes, hair or skin, and how far
the garment stands off the body (offsets along the rest-pose normals, so that the clothed mesh keeps the
body's topology and skinning, like the avatar's morphed mesh).

Everything is computed on Anny's rest pose (A-pose, Z-up, facing −Y, metres) from the vertices'
dominant bones and from positions along each limb (0 at the shoulder/hip joint, 1 at the wrist/ankle).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["GARMENTS", "Garments", "dress"]

# Label values; a face takes the highest-priority label among its corners (garments sit on top of skin).
GARMENTS = ("skin", "hair", "shoes", "trousers", "shirt", "collar", "hood")
SKIN, HAIR, SHOES, TROUSERS, SHIRT, COLLAR, HOOD = range(len(GARMENTS))


@dataclass
class Garments:
    """vertex_labels [V] and face_labels [F] (indices into ``GARMENTS``), offsets [V] in metres along
    the rest normals, and per-vertex limb coordinates (arm_s, leg_s in [0, 1] on limbs, −1 elsewhere)
    that the texture uses for cuffs and hems; ``landmarks`` holds named rest positions/heights."""

    vertex_labels: np.ndarray
    face_labels: np.ndarray
    offsets: np.ndarray
    arm_s: np.ndarray
    leg_s: np.ndarray
    landmarks: dict


def _smoothstep(a: float, b: float, x: np.ndarray) -> np.ndarray:
    t = np.clip((x - a) / (b - a), 0.0, 1.0)
    return t * t * (3 - 2 * t)


def _limb_coordinate(v: np.ndarray, start: np.ndarray, end: np.ndarray) -> np.ndarray:
    axis = end - start
    return ((v - start) @ axis) / (axis @ axis)


# Body-part group of a vertex, by the prefix of its dominant bone's name (later rows win; "torso" else).
_GROUPS = (
    ("neck", "neck"),
    ("head", "head"),
    ("eye", "head"),
    ("wrist", "hand"),
    ("finger", "hand"),
    ("metacarpal", "hand"),
    ("foot", "foot"),
    ("toe", "foot"),
    ("upperleg", "leg"),
    ("lowerleg", "leg"),
    ("shoulder", "arm"),
    ("upperarm", "arm"),
    ("lowerarm", "arm"),
    ("root", "hips"),
    ("pelvis", "hips"),
)


def dress(
    rest: np.ndarray,
    faces: np.ndarray,
    dominant_bone: np.ndarray,
    bone_names: tuple[str, ...],
    joints: dict[str, np.ndarray],
    sleeve_end: float = 0.9,
    flare: float = 1.0,
) -> Garments:
    """Label and offset the rest-pose body ``rest`` [V, 3].

    dominant_bone: [V] bone index with the largest skin weight; joints: rest head position [3] per bone
    name (needs upperarm01/wrist/upperleg01/foot for both sides, neck01, head). ``sleeve_end`` is where
    the sleeves stop along the arm; ``flare`` scales how loose sleeves and trouser legs get.
    """
    names = np.array(bone_names)[dominant_bone].astype(str)
    group = np.full(len(rest), "torso", dtype=object)
    for prefix, g in _GROUPS:
        group[np.char.startswith(names, prefix)] = g
    arm_s, leg_s = _limb_coordinates(rest, group, joints)
    neck_z = joints["neck01"][2]
    hip_z = 0.5 * (joints["upperleg01.L"][2] + joints["upperleg01.R"][2])
    hem_z = hip_z - 0.05  # the shirt hangs over the trousers' waistband
    labels = np.full(len(rest), SKIN, np.int64)
    offsets = np.zeros(len(rest))
    _clothes(rest[:, 2], group, arm_s, leg_s, hem_z, sleeve_end, flare, labels, offsets)
    back_y = _collar_and_hood(rest, group, neck_z, labels, offsets)
    _hair(rest, group, joints, neck_z, labels, offsets)

    face_labels = labels[faces].max(axis=1)
    landmarks = {
        "neck_z": neck_z,
        "head_z": joints["head"][2],
        "hip_z": hip_z,
        "hem_z": hem_z,
        "chest_z": 0.5 * (neck_z + hem_z) + 0.07,
        "floor_z": float(rest[:, 2].min()),
        "head_c": joints["head"],
        "back_y": back_y,
        "sleeve_end": sleeve_end,
    }
    return Garments(labels, face_labels, offsets.astype(np.float32), arm_s, leg_s, landmarks)


def _limb_coordinates(rest: np.ndarray, group: np.ndarray, joints: dict) -> tuple[np.ndarray, np.ndarray]:
    """(arm_s, leg_s) [V]: 0 at the shoulder / hip joint, 1 at the wrist / ankle, -1 off the limb."""
    left = rest[:, 0] > 0
    arm_s = np.full(len(rest), -1.0)
    leg_s = np.full(len(rest), -1.0)
    for side, mask in (("L", left), ("R", ~left)):
        arm = mask & np.isin(group, ["arm", "hand"])
        arm_s[arm] = _limb_coordinate(rest[arm], joints[f"upperarm01.{side}"], joints[f"wrist.{side}"])
        leg = mask & np.isin(group, ["leg", "foot"])
        leg_s[leg] = _limb_coordinate(rest[leg], joints[f"upperleg01.{side}"], joints[f"foot.{side}"])
    return arm_s, leg_s


def _clothes(z, group, arm_s, leg_s, hem_z: float, sleeve_end: float, flare: float, labels, offsets) -> None:
    """Trousers, then the shirt over them, then shoes: labels and offsets written in place."""
    trousers = np.isin(group, ["hips", "leg"]) | ((group == "torso") & (z < hem_z + 0.08))
    trousers &= ~((group == "leg") & (leg_s > 1.02))
    labels[trousers] = TROUSERS
    offsets[trousers] = 0.010 + 0.035 * flare * _smoothstep(0.4, 1.0, np.maximum(leg_s[trousers], 0))

    shirt = (group == "torso") | ((group == "hips") & (z > hem_z)) | ((group == "arm") & (arm_s < sleeve_end))
    labels[shirt] = SHIRT
    hem = _smoothstep(hem_z + 0.12, hem_z, z[shirt])  # loosen towards the hem
    sleeve = _smoothstep(0.45, sleeve_end, np.maximum(arm_s[shirt], 0))
    offsets[shirt] = 0.012 + 0.012 * hem + 0.032 * flare * sleeve

    feet = (group == "foot") | ((group == "leg") & (leg_s > 1.02))
    labels[feet] = SHOES
    offsets[feet] = 0.010


def _collar_and_hood(rest, group, neck_z: float, labels, offsets) -> float:
    """The collar, and a folded hood lying on the upper back (+Y is the back: a soft bump), in place.
    Returns the back's y (the torso's 90th percentile)."""
    x, y, z = rest.T
    collar = np.isin(group, ["neck", "torso"]) & (z > neck_z - 0.03) & (z < neck_z + 0.045)
    labels[collar] = COLLAR
    offsets[collar] = 0.018 + 0.006 * _smoothstep(neck_z - 0.03, neck_z + 0.045, z[collar])

    back_y = np.percentile(y[group == "torso"], 90)
    hood_c = np.array([0.0, back_y, neck_z - 0.07])
    r2 = (x / 0.13) ** 2 + ((z - hood_c[2]) / 0.075) ** 2
    hood = np.isin(group, ["torso", "neck"]) & (y > hood_c[1] - 0.09) & (r2 < 1.0)
    labels[hood] = HOOD
    offsets[hood] = np.maximum(offsets[hood], 0.012 + 0.045 * (1 - r2[hood]))
    return back_y


def _hair(rest, group, joints: dict, neck_z: float, labels, offsets) -> None:
    """Hair: scalp above the forehead, and the back of the head down to the nape (in place)."""
    _, y, z = rest.T
    head_z = joints["head"][2]
    head_c = joints["head"]
    scalp = (group == "head") & ((z > head_z + 0.115) | ((y > head_c[1] + 0.005) & (z > neck_z + 0.04)))
    labels[scalp] = HAIR
    offsets[scalp] = 0.008 + 0.014 * _smoothstep(head_z + 0.05, head_z + 0.2, z[scalp])
