"""Motion files (BVH, AMASS / SMPL-X npz) retargeted onto Anny: posed Anny bones point where the
source's do. Figures: ``python3 benchmarks/retarget_errors.py``."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gma.core.errors import InputError

# A CMU-style skeleton (Y up, facing +Z, body left +X, centimetres) in a T-pose: joint, parent, offset.
CMU_TPOSE = (
    ("Hips", None, (0, 0, 0)),
    ("LeftUpLeg", "Hips", (9, -5, 0)), ("LeftLeg", "LeftUpLeg", (0, -42, 0)), ("LeftFoot", "LeftLeg", (0, -41, 0)),
    ("RightUpLeg", "Hips", (-9, -5, 0)), ("RightLeg", "RightUpLeg", (0, -42, 0)),
    ("RightFoot", "RightLeg", (0, -41, 0)),
    ("Spine", "Hips", (0, 10, 0)), ("Spine1", "Spine", (0, 18, 0)), ("Neck", "Spine1", (0, 22, 0)),
    ("Head", "Neck", (0, 10, 0)),
    ("LeftShoulder", "Spine1", (4, 18, 0)), ("LeftArm", "LeftShoulder", (14, 0, 0)),
    ("LeftForeArm", "LeftArm", (28, 0, 0)), ("LeftHand", "LeftForeArm", (25, 0, 0)),
    ("RightShoulder", "Spine1", (-4, 18, 0)), ("RightArm", "RightShoulder", (-14, 0, 0)),
    ("RightForeArm", "RightArm", (-28, 0, 0)), ("RightHand", "RightForeArm", (-25, 0, 0)),
)
# Known rotations per frame (degrees, BVH channel order Z X Y) and root positions (cm).
BVH_FRAMES = (
    {},
    {"LeftLeg": (0, 60, 0), "RightForeArm": (0, 0, 90), "LeftArm": (-45, 0, 0), "Spine": (0, 20, 0)},
    {"Hips": (0, 0, 90), "LeftUpLeg": (0, -40, 0), "RightUpLeg": (0, 30, 0), "LeftForeArm": (0, 0, -70),
     "Neck": (10, 0, 20)},
)
BVH_ROOT = ((0, 93, 0), (0, 93, 20), (30, 90, 40))


def write_bvh(path, frames=BVH_FRAMES, roots=BVH_ROOT, frame_time=1 / 60):
    children = {}
    for name, parent, _ in CMU_TPOSE:
        children.setdefault(parent, []).append(name)
    offsets = {n: o for n, _, o in CMU_TPOSE}
    lines, order = ["HIERARCHY"], []

    def joint(name, depth):
        pad = "  " * depth
        root = depth == 0
        lines.append(f"{pad}{'ROOT' if root else 'JOINT'} {name}")
        lines.append(pad + "{")
        lines.append(f"{pad}  OFFSET {' '.join(str(float(v)) for v in offsets[name])}")
        chans = "6 Xposition Yposition Zposition" if root else "3"
        lines.append(f"{pad}  CHANNELS {chans} Zrotation Xrotation Yrotation")
        order.append(name)
        for c in children.get(name, []):
            joint(c, depth + 1)
        if name not in children:
            lines.extend([f"{pad}  End Site", pad + "  {", f"{pad}    OFFSET 0.0 -5.0 0.0", pad + "  }"])
        lines.append(pad + "}")

    joint("Hips", 0)
    lines += ["MOTION", f"Frames: {len(frames)}", f"Frame Time: {frame_time}"]
    for rot, root in zip(frames, roots):
        vals = []
        for n in order:
            if n == "Hips":
                vals += list(root)
            vals += list(rot.get(n, (0, 0, 0)))
        lines.append(" ".join(f"{v:g}" for v in vals))
    path.write_text("\n".join(lines) + "\n")


def posed_heads(body, pose: torch.Tensor) -> np.ndarray:
    """[T, J, 3] posed bone heads of Anny for poses [T, J, 4, 4]."""
    from gma.body.retarget import rest_heads

    heads = torch.from_numpy(rest_heads(body)).float()
    with torch.no_grad():
        tr = body.bone_transforms({"pose": pose, "shape": body.param_spaces["shape"].default_tensor()})
    return ((tr[..., :3, :3] @ heads[:, :, None])[..., 0] + tr[..., :3, 3]).numpy()


def angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    a = a / np.linalg.norm(a, axis=-1, keepdims=True)
    b = b / np.linalg.norm(b, axis=-1, keepdims=True)
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


# (Anny bone, its direction child; BVH joint, its child) compared in the BVH test.
BVH_BONES = (
    ("upperleg01.L", "lowerleg01.L", "LeftUpLeg", "LeftLeg"), ("lowerleg01.L", "foot.L", "LeftLeg", "LeftFoot"),
    ("upperleg01.R", "lowerleg01.R", "RightUpLeg", "RightLeg"), ("lowerleg01.R", "foot.R", "RightLeg", "RightFoot"),
    ("upperarm01.L", "lowerarm01.L", "LeftArm", "LeftForeArm"), ("lowerarm01.L", "wrist.L", "LeftForeArm", "LeftHand"),
    ("upperarm01.R", "lowerarm01.R", "RightArm", "RightForeArm"),
    ("lowerarm01.R", "wrist.R", "RightForeArm", "RightHand"),
)


def bvh_direction_errors(body, path) -> np.ndarray:
    """[T, B] angle (degrees) between each limb of the retargeted Anny and the BVH's, per frame."""
    from gma.body.motion_files import load_motion_file, parse_bvh
    from gma.body.retarget import axes_from_skeleton

    motion = load_motion_file(path, body)
    heads = posed_heads(body, motion.pose)
    bvh = parse_bvh(path)
    _, pos = bvh.forward_kinematics()
    rest = bvh.rest_positions()
    ix = {n: i for i, n in enumerate(bvh.names)}
    axes = axes_from_skeleton(rest[ix["LeftUpLeg"]] - rest[ix["RightUpLeg"]], rest[ix["Head"]] - rest[ix["Hips"]])
    b = body.bone_names
    err = []
    for a, ac, s, sc in BVH_BONES:
        d_anny = heads[:, b.index(ac)] - heads[:, b.index(a)]
        d_src = (pos[:, ix[sc]] - pos[:, ix[s]]) @ axes.T
        err.append(angle_deg(d_anny, d_src))
    return np.stack(err, 1)


@pytest.mark.slow
def test_bvh_limbs_follow_the_source(anny_body, tmp_path):
    write_bvh(tmp_path / "m.bvh")
    err = bvh_direction_errors(anny_body, tmp_path / "m.bvh")
    assert err.max() < 0.5, err.round(2)


@pytest.mark.slow
def test_bvh_known_rotations_and_root(anny_body, tmp_path):
    from gma.body.motion_files import load_motion_file

    write_bvh(tmp_path / "m.bvh")
    m = load_motion_file(tmp_path / "m.bvh", anny_body)
    assert len(m) == 3 and m.fps == pytest.approx(60.0)
    knee = m.pose[1, anny_body.bone_index("lowerleg01.L"), :3, :3].double()
    # 60° about the BVH's X (the body's left axis) is a rotation about Anny's X; Anny's rest knee is already
    # bent ~10° (the BVH's is straight), so the delta is smaller and the posed thigh-shin angle is 60°.
    assert knee[0, 0] > 0.99
    heads = posed_heads(anny_body, m.pose)[1]
    b = anny_body.bone_names
    thigh = heads[b.index("lowerleg01.L")] - heads[b.index("upperleg01.L")]
    shin = heads[b.index("foot.L")] - heads[b.index("lowerleg01.L")]
    assert abs(float(angle_deg(thigh, shin)) - 60.0) < 2.0
    # Root: 20 cm forward in the BVH (+Z) is forward for Anny (−Y), scaled to Anny's legs; frame 0 at the origin.
    root = m.pose[:, 0, :3, 3]
    assert root[0, :2].abs().max() < 1e-5
    assert -0.25 < float(root[1, 1]) < -0.12 and abs(float(root[1, 0])) < 1e-4
    # Turned 90° about up in frame 2: Anny's root turns 90° about Z.
    r2 = m.pose[2, 0, :3, :3]
    assert abs(float(r2[2, 2]) - 1) < 1e-4 and abs(float(r2[0, 0])) < 1e-4


@pytest.mark.slow
def test_resampling_keeps_duration(anny_body, tmp_path):
    from gma.body.motion_files import load_motion_file

    write_bvh(tmp_path / "m.bvh", frame_time=1 / 20)
    m = load_motion_file(tmp_path / "m.bvh", anny_body, fps=40)
    assert len(m) == 5 and m.fps == 40
    src = load_motion_file(tmp_path / "m.bvh", anny_body)
    torch.testing.assert_close(m.pose[2], src.pose[1], atol=1e-5, rtol=0)  # a source frame is kept exactly


def write_amass(path, poses: dict[int, tuple[float, float, float]], frames: int = 3, rate=60.0):
    """An AMASS-style SMPL-X npz: root turned upright (Z-up world), ``poses`` joint -> axis-angle from frame 1."""
    p = np.zeros((frames, 165))
    p[:, :3] = (np.pi / 2, 0, 0)  # the Y-up model stands up in AMASS's Z-up world, facing −Y
    for j, aa in poses.items():
        p[1:, 3 * j:3 * j + 3] = aa
    trans = np.zeros((frames, 3))
    trans[:, 1] = -np.linspace(0, 0.5, frames)  # walking forward (−Y)
    trans[:, 2] = 0.95
    np.savez(path, poses=p, trans=trans, mocap_framerate=np.array(rate), betas=np.zeros(16))


def amass_direction_errors(body, path, expected: dict[tuple[str, str], np.ndarray]) -> np.ndarray:
    from gma.body.motion_files import load_motion_file

    m = load_motion_file(path, body)
    heads = posed_heads(body, m.pose)
    b = body.bone_names
    return np.array([angle_deg(heads[-1, b.index(c)] - heads[-1, b.index(a)], d) for (a, c), d in expected.items()])


AMASS_POSES = {4: (1.0, 0.0, 0.0), 19: (0.0, 1.2, 0.0), 16: (0.0, 0.0, -0.6), 1: (-0.8, 0.0, 0.0)}


def amass_expected(body) -> dict[tuple[str, str], np.ndarray]:
    """Where the limbs of AMASS_POSES point in Anny's world (Anny axes = SMPL's turned upright)."""
    from gma.body.retarget import rest_heads

    heads = rest_heads(body)
    b = body.bone_names

    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def rest(a, c):
        return heads[b.index(c)] - heads[b.index(a)]

    # SMPL (x, y, z) -> Anny (x, -z, y); a rotation about SMPL's Y is one about Anny's −(−Z)... computed directly:
    c = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)
    hip = c @ rx(-0.8) @ c.T
    knee = c @ rx(1.0) @ c.T
    el = 1.2  # right forearm, T-pose (−1, 0, 0) in SMPL, turned about SMPL Y
    forearm = c @ np.array([-np.cos(el), 0, np.sin(el)])
    sh = -0.6  # left upper arm (1, 0, 0) turned about SMPL Z: down
    upper = c @ np.array([np.cos(sh), np.sin(sh), 0])
    return {("upperleg01.L", "lowerleg01.L"): hip @ rest("upperleg01.L", "lowerleg01.L"),
            ("lowerleg01.L", "foot.L"): hip @ knee @ rest("lowerleg01.L", "foot.L"),
            ("lowerarm01.R", "wrist.R"): forearm, ("upperarm01.L", "lowerarm01.L"): upper}


@pytest.mark.slow
def test_amass_npz_limbs_follow_the_source(anny_body, tmp_path):
    write_amass(tmp_path / "a.npz", AMASS_POSES)
    err = amass_direction_errors(anny_body, tmp_path / "a.npz", amass_expected(anny_body))
    assert err.max() < 0.5, err.round(2)


@pytest.mark.slow
def test_root_follows_and_feet_stay_on_the_floor(anny_body, tmp_path):
    from gma.body.motion_files import load_motion_file

    write_amass(tmp_path / "a.npz", {}, frames=4)
    m = load_motion_file(tmp_path / "a.npz", anny_body, fps=30)
    root = m.pose[:, 0, :3, 3]
    np.testing.assert_allclose(root[:, 1].numpy(), -np.linspace(0, 0.5, 4)[::2], atol=1e-5)  # 60 -> 30 fps
    rest_low = posed_heads(anny_body, anny_body.canonical_pose()[None])[0, :, 2].min()
    assert np.allclose(root[:, 2].numpy(), root[0, 2].item())  # constant height stays constant
    feet = [anny_body.bone_index(n) for n in ("foot.L", "foot.R")]
    low = posed_heads(anny_body, m.pose)[:, feet, 2].min()
    assert low == pytest.approx(posed_heads(anny_body, anny_body.canonical_pose()[None])[0, feet, 2].min(), abs=2e-3)
    assert rest_low <= low


@pytest.mark.parametrize("text,msg", [
    ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Xrotation Yrotation Zrotation\n}\nMOTION\nFrames: 2\n"
     "Frame Time: 0.1\n0 0 0\n", "motion values"),
    ("hello", "no HIERARCHY"),
    ("HIERARCHY\nROOT Hips\n{\nOFFSET 0 0 0\nCHANNELS 3 Qrotation Yrotation Zrotation\n}\nMOTION\nFrames: 1\n"
     "Frame Time: 0.1\n0 0 0\n", "unknown channels"),
])
def test_bad_bvh_is_named(tmp_path, text, msg):
    from gma.body.motion_files import parse_bvh

    (tmp_path / "b.bvh").write_text(text)
    with pytest.raises(InputError, match=msg):
        parse_bvh(tmp_path / "b.bvh")


@pytest.mark.slow
def test_import_motion_cli_writes_an_anny_motion(anny_body, tmp_path):
    from gma.body.motion_files import load_motion_file
    from gma.cli import main

    write_bvh(tmp_path / "m.bvh")
    assert main(["import", "motion", str(tmp_path / "m.bvh"), str(tmp_path / "m.npz"), "--fps", "30"]) == 0
    saved = load_motion_file(tmp_path / "m.npz", anny_body)
    direct = load_motion_file(tmp_path / "m.bvh", anny_body, fps=30)
    assert saved.fps == 30 and len(saved) == len(direct) == 2
    torch.testing.assert_close(saved.pose, direct.pose)


@pytest.mark.slow
@pytest.mark.parametrize("name,down", [("tpose", 0.0), ("apose", 45.0)])
def test_named_poses_hold_the_arms(anny_body, name, down):
    from gma.body.retarget import reference_pose

    heads = posed_heads(anny_body, reference_pose(anny_body, name)["pose"][None])[0]
    b = anny_body.bone_names
    for side, sign in (("L", 1.0), ("R", -1.0)):
        for a, c in ((f"upperarm01.{side}", f"lowerarm01.{side}"), (f"lowerarm01.{side}", f"wrist.{side}")):
            want = np.array([sign * np.cos(np.radians(down)), 0.0, -np.sin(np.radians(down))])
            assert angle_deg(heads[b.index(c)] - heads[b.index(a)], want) < 2.0
