"""Correspondence between MediaPipe landmarks and points of the Anny body.

Model points are named ``coco:<name>`` (Anny's own COCO keypoint regressor, ``anny.keypoints``: a
fixed blend of surface vertices, so it follows the shape), ``head:<bone>`` (the joint at the start
of an Anny bone) or ``tip:<bone>`` (the surface vertex farthest along the bone — fingertips, which no
joint marks). Weights say how much each landmark is trusted: MediaPipe's face and foot points sit on
the surface where Anny's COCO regressor agrees well; its hip points sit higher and wider than a
skeleton's hip joints, so they count less.

MediaPipe pose (33 landmarks) → Anny:

====  ==================  =========================  ======
idx   MediaPipe           Anny point                 weight
====  ==================  =========================  ======
0     nose                coco:nose                  1.0
2/5   left/right eye      coco:left_eye / right_eye  0.5
7/8   left/right ear      coco:left_ear / right_ear  0.5
11/12 shoulders           coco:left/right_shoulder   1.0
13/14 elbows              coco:left/right_elbow      1.0
15/16 wrists              coco:left/right_wrist      1.0
17/18 pinky knuckles      head:finger5-1.L/R         0.3
19/20 index knuckles      head:finger2-1.L/R         0.3
21/22 thumbs              head:finger1-3.L/R         0.3
23/24 hips                coco:left/right_hip        0.7
25/26 knees               coco:left/right_knee       1.0
27/28 ankles              coco:left/right_ankle      1.0
29/30 heels               coco:left/right_heel       0.5
31/32 foot index (toes)   coco:left/right_big_toe    0.5
====  ==================  =========================  ======

The inner/outer eye corners (1, 3, 4, 6) and mouth corners (9, 10) have no Anny counterpart and are
not used. MediaPipe hand (21 landmarks per hand): 0 wrist → ``head:wrist``; thumb 1–4 →
``head:finger1-1``, ``head:finger1-2``, ``head:finger1-3``, ``tip:finger1-3``; index 5–8, middle 9–12,
ring 13–16, pinky 17–20 → ``head:fingerN-1``, ``head:fingerN-2``, ``head:fingerN-3``,
``tip:fingerN-3`` with N = 2, 3, 4, 5. Anny's "left" (``.L``, +X) is the person's left, as MediaPipe's.

MediaPipe face mesh: the centres of the eyes, each the mean of its two corners
(``gma.video.detect.FACE_MESH_POINTS``) → ``coco:left_eye``, ``coco:right_eye``. Only the
3D direction between the eyes is used (``FACE_PAIRS``): the face mesh's depth is relative and its scale
loose, but the line between the eyes tilts with the head's turn and roll.
"""

from __future__ import annotations

import numpy as np

__all__ = [
    "BONE_PAIRS",
    "BONE_PAIR_WEIGHTS",
    "FACE_PAIRS",
    "FACE_PAIR_WEIGHTS",
    "FACE_POINTS",
    "HAND_POINTS",
    "POSE_FLIP",
    "POSE_POINTS",
    "POSE_WEIGHTS",
    "hand_points",
    "model_point_names",
]

# (MediaPipe pose index, Anny point, weight)
_POSE_TABLE = [
    (0, "coco:nose", 1.0),
    (2, "coco:left_eye", 0.5), (5, "coco:right_eye", 0.5),
    (7, "coco:left_ear", 0.5), (8, "coco:right_ear", 0.5),
    (11, "coco:left_shoulder", 1.0), (12, "coco:right_shoulder", 1.0),
    (13, "coco:left_elbow", 1.0), (14, "coco:right_elbow", 1.0),
    (15, "coco:left_wrist", 1.0), (16, "coco:right_wrist", 1.0),
    (17, "head:finger5-1.L", 0.3), (18, "head:finger5-1.R", 0.3),
    (19, "head:finger2-1.L", 0.3), (20, "head:finger2-1.R", 0.3),
    (21, "head:finger1-3.L", 0.3), (22, "head:finger1-3.R", 0.3),
    (23, "coco:left_hip", 0.7), (24, "coco:right_hip", 0.7),
    (25, "coco:left_knee", 1.0), (26, "coco:right_knee", 1.0),
    (27, "coco:left_ankle", 1.0), (28, "coco:right_ankle", 1.0),
    (29, "coco:left_heel", 0.5), (30, "coco:right_heel", 0.5),
    (31, "coco:left_big_toe", 0.5), (32, "coco:right_big_toe", 0.5),
]

POSE_POINTS: list[str | None] = [None] * 33
POSE_WEIGHTS = np.zeros(33, np.float32)
for _i, _name, _w in _POSE_TABLE:
    POSE_POINTS[_i] = _name
    POSE_WEIGHTS[_i] = _w

# MediaPipe pose index of the same landmark on the other side (what a left/right swap exchanges).
POSE_FLIP = np.array([0, 4, 5, 6, 1, 2, 3, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15, 18, 17, 20, 19, 22, 21,
                      24, 23, 26, 25, 28, 27, 30, 29, 32, 31])

# Bones whose 3D direction is compared with MediaPipe's world landmarks (pose indices, from → to).
BONE_PAIRS = [
    (11, 13), (13, 15), (12, 14), (14, 16),  # arms
    (23, 25), (25, 27), (24, 26), (26, 28),  # legs
    (12, 11), (24, 23),                      # shoulder and hip lines (body orientation)
    (23, 11), (24, 12),                      # flanks (torso lean)
    (27, 31), (28, 32),                      # feet
]
# Weight of each pair's 3D direction in the fit (× FitConfig.w_3d). The arms need it: only MediaPipe's
# depth tells a forearm pointing at the camera from one pointing away (on a 10-frame turn, arms came out
# 43-65° off at a tenth of it). Elsewhere its bias costs more than it settles: on a 40-frame synthetic
# turn, legs, feet and torso lines at full weight left the feet 33-45° off, the lower legs 24-32° and
# the root 8°; at a tenth, 12-13°, 9-10° and 6.5° (benchmarks/video_to_avatar.py, docs/fitting.md).
BONE_PAIR_WEIGHTS = [1.0] * 4 + [0.1] * 10

# The face mesh's points (in gma.video.detect.FACE_MESH_POINTS' order) and the Anny points they are.
FACE_POINTS = ("coco:left_eye", "coco:right_eye")
# Face points whose 3D direction is compared (indices into FACE_POINTS, from → to): the eye line, which
# turns with the head's turn and roll. The eyes-to-nose lines would add its nod, but the face mesh puts
# the nose further toward the camera than Anny's: on the iPER clip they stayed 11° off the fitted
# body's, always leaning the same way, and pulled the head 10° on average (the eye line alone: 6°)
# while the body's 2D landmarks fitted worse (5.86 px against 5.70 without the face mesh, 5.57 with
# the eye line alone).
FACE_PAIRS = [(1, 0)]
FACE_PAIR_WEIGHTS = [1.0]


def hand_points(side: str) -> list[str]:
    """The 21 Anny points matching MediaPipe's hand landmarks; ``side`` is "L" or "R"."""
    pts = [f"head:wrist.{side}"]
    for n in range(1, 6):
        pts += [f"head:finger{n}-1.{side}", f"head:finger{n}-2.{side}", f"head:finger{n}-3.{side}",
                f"tip:finger{n}-3.{side}"]
    return pts


HAND_POINTS = {"L": hand_points("L"), "R": hand_points("R")}


def model_point_names() -> list[str]:
    """Every Anny point the fit uses, in a fixed order: pose points, then left and right hand points."""
    names: list[str] = []
    for p in [p for p in POSE_POINTS if p is not None] + HAND_POINTS["L"] + HAND_POINTS["R"]:
        if p not in names:
            names.append(p)
    return names
