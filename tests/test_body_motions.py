"""Built-in motions and Anny pose sequences from body.npz."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from gma.body.motions import MOTIONS, axis_angle_to_matrix, load_anny_motion, motion


def test_axis_angle_to_matrix():
    aa = torch.tensor([[0.0, 0, 0], [0, 0, np.pi / 2], [1e-9, 0, 0]])
    r = axis_angle_to_matrix(aa)
    torch.testing.assert_close(r[0], torch.eye(3))
    torch.testing.assert_close(r[1] @ torch.tensor([1.0, 0, 0]), torch.tensor([0.0, 1, 0]), atol=1e-6, rtol=0)
    torch.testing.assert_close(r[2], torch.eye(3))


@pytest.mark.parametrize("name", MOTIONS)
def test_builtin_motion_is_a_real_loop(anny_body, name):
    m = motion(name, 24, anny_body)
    assert m.pose.shape == (24, 104, 4, 4) and m.expression.shape == (24, 52) and len(m) == 24
    rot = m.pose[..., :3, :3]
    torch.testing.assert_close(rot @ rot.transpose(-1, -2), torch.eye(3).expand_as(rot), atol=1e-5, rtol=0)
    verts = torch.stack([anny_body.pose(m.params(t)).vertices for t in (0, 6, 12)])
    if name == "expressions":
        assert m.expression.max() > 0.5 and float(m.expression.min()) >= 0
        rest = torch.stack([anny_body.rest_vertices({"expression": m.expression[t]}) for t in (0, 6, 12)])
        assert (rest[1:] - rest[:1]).norm(dim=-1).max() > 2e-3  # the face moves
    else:
        assert (verts[1:] - verts[:1]).norm(dim=-1).max() > 0.05  # the body moves (metres)
    # Seamless loop: the frame after the last is the first.
    torch.testing.assert_close(m.params(24)["pose"], m.pose[0])


def test_turn_rotates_about_up_axis(anny_body):
    m = motion("turn", 4, anny_body)
    v0 = anny_body.pose(m.params(0)).vertices
    v1 = anny_body.pose(m.params(1)).vertices  # a quarter turn
    torch.testing.assert_close(v1[:, 2], v0[:, 2], atol=1e-4, rtol=0)  # heights unchanged
    torch.testing.assert_close(v1[:, 0], -v0[:, 1], atol=1e-4, rtol=0)


def test_wave_raises_the_right_hand(anny_body):
    m = motion("wave", 20, anny_body)
    v = anny_body.pose(m.params(10)).vertices
    right_hand = anny_body.region_mask("hand.R")
    hand_z = v[anny_body.faces[right_hand].flatten(), 2].mean()
    head_z = v[anny_body.faces[anny_body.regions["head"]].flatten(), 2].min()
    assert hand_z > head_z


def test_unknown_motion():
    with pytest.raises(ValueError, match="built-in motions: turn, walk"):
        motion("dance", 10, body=object())


def test_load_anny_motion(tmp_path, anny_body):
    src = motion("walk", 5, anny_body)
    np.savez(tmp_path / "body.npz", model="anny", pose=src.pose.numpy(),
             phenotype=np.full(6, 0.4, np.float32), facial_actions=np.zeros((5, 52), np.float32))
    m = load_anny_motion(tmp_path / "body.npz")
    assert len(m) == 5
    torch.testing.assert_close(m.pose, src.pose)
    torch.testing.assert_close(m.shape, torch.full((6,), 0.4))
    assert anny_body.pose(m.params(2)).vertices.shape == (anny_body.num_vertices, 3)


def test_load_anny_motion_rejects_other_models(tmp_path):
    np.savez(tmp_path / "body.npz", model="smplx", betas=np.zeros(10), global_orient=np.zeros((2, 3)),
             body_pose=np.zeros((2, 63)), transl=np.zeros((2, 3)), gender="neutral")
    with pytest.raises(ValueError, match="not an Anny pose sequence"):
        load_anny_motion(tmp_path / "body.npz")
