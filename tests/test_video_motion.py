"""``gma import motion clip.mp4``: the motion of a synthetic clip (known poses) recovered through the
video import's detection and body fit."""

from __future__ import annotations

import numpy as np
import pytest
import torch

# Mean angle between fitted and true limbs, in the root's frame (degrees). The video import's own test
# bounds the same fit at 8 px mean joint error on this 192 px clip, where a forearm is ~25 px long: that
# is ~20° on an arm; the arms come out above that mean and the legs well below it (the motion import
# adds nothing: it only turns and lifts the root, which these root-relative directions do not see).
LIMB_DEG = 25.0
LIMBS = (("upperarm01.L", "lowerarm01.L"), ("lowerarm01.L", "wrist.L"), ("upperarm01.R", "lowerarm01.R"),
         ("lowerarm01.R", "wrist.R"), ("upperleg01.L", "lowerleg01.L"), ("lowerleg01.L", "foot.L"),
         ("upperleg01.R", "lowerleg01.R"), ("lowerleg01.R", "foot.R"))


def root_frame_limbs(body, pose: torch.Tensor) -> np.ndarray:
    """[T, L, 3] unit limb directions in the root's own frame (independent of where the body stands)."""
    from gma.body.retarget import rest_heads

    heads = torch.from_numpy(rest_heads(body)).float()
    with torch.no_grad():
        tr = body.bone_transforms({"pose": pose, "shape": body.param_spaces["shape"].default_tensor()})
    posed = (tr[..., :3, :3] @ heads[:, :, None])[..., 0] + tr[..., :3, 3]
    b = body.bone_names
    d = torch.stack([posed[:, b.index(c)] - posed[:, b.index(a)] for a, c in LIMBS], 1)
    d = torch.einsum("tji,tlj->tli", pose[:, 0, :3, :3], d)  # R_root^T d
    return torch.nn.functional.normalize(d, dim=-1).numpy()


@pytest.mark.slow
def test_motion_from_synthetic_video(tmp_path, synth_clip, anny_body):
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.body.motion_files import load_motion_file
    from gma.video import FitConfig, VideoImportConfig
    from gma.video.motion import estimate_motion

    seq, clip = synth_clip
    vcfg = VideoImportConfig(focal=float(seq.cameras.K[0, 0, 0]),
                             fit=FitConfig(iters_root=40, iters_pose=150, iters_shape=6))
    motion, report = estimate_motion(clip, tmp_path / "m.npz", config=vcfg, progress=False, anny=anny_body)
    assert len(motion) == 10 and report["frames_detected"] == 10
    assert report["mask_check"]["applied"]  # the shape fit saw the masks checked against the background
    assert motion.fps == pytest.approx(10.0)
    back = load_motion_file(tmp_path / "m.npz", anny_body)
    torch.testing.assert_close(back.pose, motion.pose)
    truth = torch.as_tensor(seq.body.arrays["pose"]).float()
    err = np.degrees(np.arccos(np.clip((root_frame_limbs(anny_body, motion.pose)
                                        * root_frame_limbs(anny_body, truth)).sum(-1), -1, 1)))
    print(f"limb direction error vs truth: mean {err.mean():.1f} deg, per limb {err.mean(0).round(1)}, "
          f"reprojection {report['reprojection_error_px_mean']:.2f} px")  # figures with pytest -s
    assert err.mean() < LIMB_DEG, f"mean limb error {err.mean():.1f} deg (per limb {err.mean(0).round(1)})"
    # Upright in Anny's world: the root's up axis close to +Z on average, feet on the floor.
    assert float(motion.pose[:, 0, 2, 2].mean()) > 0.9


def test_no_person_is_a_clear_error(tmp_path, empty_room_clip):
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.video.motion import estimate_motion

    clip = empty_room_clip
    with pytest.raises(ValueError, match="no person detected"):
        estimate_motion(clip, tmp_path / "m.npz", progress=False)
    assert not (tmp_path / "m.npz").exists() and not (tmp_path / "m.npz.work").exists()
    # A bad feet mode is refused before the video is even read.
    with pytest.raises(ValueError, match="feet must be"):
        estimate_motion(tmp_path / "missing.mp4", tmp_path / "m.npz", feet="ground", progress=False)
