"""The video pipeline (gma.video): reading videos with clear errors, left/right swap resolution, the body
fit against ground-truth landmarks (no MediaPipe needed), and — when MediaPipe is installed — the whole
``gma import video clip.mp4 OUT`` on a synthetic clip with known ground truth."""

from __future__ import annotations

import json
import logging
import os
from pathlib import Path

import numpy as np
import pytest
import roma
import torch

# Bounds for a 10-frame, 192 px synthetic turn (36° per frame, back views included).
GT_LANDMARK_PX = 6.0  # fit to exact landmarks: mean joint error (px)
PIPELINE_JOINT_PX = 8.0  # full pipeline (MediaPipe landmarks): mean joint error against the truth (px)
PIPELINE_IOU = 0.6  # fitted (unclothed) body vs MediaPipe's (clothed) mask
BODY_JOINTS = ["coco:left_shoulder", "coco:right_shoulder", "coco:left_elbow", "coco:right_elbow",
               "coco:left_wrist", "coco:right_wrist", "coco:left_hip", "coco:right_hip", "coco:left_knee",
               "coco:right_knee", "coco:left_ankle", "coco:right_ankle", "coco:nose"]


@pytest.fixture(scope="module")
def rig(anny_body):
    from gma.video.rig import AnnyRig

    return AnnyRig(anny_body)


def _gt_uv(rig, seq) -> np.ndarray:
    """Ground-truth pixels [T, P, 2] of the rig's model points."""
    from gma.video.fit import project

    pose = torch.as_tensor(seq.body.arrays["pose"]).float()
    rest = rig.rest(torch.as_tensor(seq.body.arrays["phenotype"]).float())
    with torch.no_grad():
        pts = rig.points(rig.transforms(pose, rest), rest)
    out = []
    for t in range(len(pose)):
        K, w2c = (torch.as_tensor(a).float() for a in seq.cameras.frame(t))
        out.append(project(pts[t], K, w2c[:3, :3], w2c[:3, 3]).numpy())
    return np.stack(out)


def _joint_error(rig, uv, gt) -> float:
    idx = [rig.index(n) for n in BODY_JOINTS]
    return float(np.linalg.norm(uv[:, idx] - gt[:, idx], axis=-1).mean())


# -- reading videos ---------------------------------------------------------------------------------
def test_bad_videos_give_clear_errors(tmp_path, synth_clip):
    from gma.video import VideoError, read_video

    _, clip = synth_clip
    frames, idx = read_video(clip)
    assert frames.shape == (10, 192, 192, 3) and idx == list(range(10))
    text = tmp_path / "notes.mp4"
    text.write_text("not a video")
    truncated = tmp_path / "cut.mp4"
    truncated.write_bytes(clip.read_bytes()[: clip.stat().st_size // 2])
    empty = tmp_path / "empty.mp4"
    empty.write_bytes(b"")
    for path in (text, truncated, empty):
        with pytest.raises(VideoError, match=path.name):
            read_video(path)
    with pytest.raises(FileNotFoundError, match="missing.mp4"):
        read_video(tmp_path / "missing.mp4")
    with pytest.raises(VideoError, match="10 frames selected, more than the limit 3"):
        read_video(clip, max_frames=3)


def test_only_the_selected_frames_are_decoded_and_kept(synth_clip, monkeypatch):
    """start / end / skip pick the frames ``frame_range`` names, and decoding stops at ``end`` (a clip
    damaged after it still imports)."""
    import gma.video.frames as video_frames
    from gma.data.importers._common import frame_range
    from gma.video import VideoError, read_video

    _, clip = synth_clip
    every, _ = read_video(clip)
    for start, end, skip in ((0, None, 3), (2, 9, 2), (5, 6, 1), (9, None, 4), (0, 4, 1), (0, None, 1)):
        info: dict = {}
        frames, idx = read_video(clip, start, end, skip, info=info)
        assert idx == frame_range(10, start, end, skip)
        assert np.array_equal(frames, every[idx])
        # The clip's frame count is known when every frame was read to the end (ffmpeg drops the frames
        # of a selection unseen, and decoding stops at `end`).
        assert info.get("frames_total") == (10 if (start, end, skip) == (0, None, 1) else None)
    with pytest.raises(ValueError, match="selects nothing of 10 frames"):
        read_video(clip, start=20, skip=2)
    with pytest.raises(ValueError, match="skip >= 1"):
        read_video(clip, skip=0)

    # Over the memory budget: refused as soon as the bytes run over, with a --skip that fits.
    frame_bytes = every[0].nbytes
    with pytest.raises(VideoError, match=r"10 frames of 192x192 selected .*use --skip 4 or --end to select at most 3"):
        read_video(clip, max_bytes=3 * frame_bytes + 10)
    frames, idx = read_video(clip, skip=4, max_bytes=3 * frame_bytes + 10)
    assert idx == [0, 4, 8]

    def damaged_after_six(path, alpha, info=None, select=None):
        """ffmpeg reading a clip whose 7th frame is damaged, with its select filter."""
        start, end, skip = select or (0, None, 1)
        for i, f in enumerate(every):
            if i == 6:
                raise RuntimeError("ffmpeg: invalid data found when processing input")
            decoded.append(i)
            if i >= start and (i - start) % skip == 0 and (end is None or i < end):
                yield f.copy()

    monkeypatch.setattr(video_frames, "read_frames", damaged_after_six)
    decoded = []
    frames, idx = read_video(clip, 1, 5, 2)
    assert idx == [1, 3] and decoded == [0, 1, 2, 3]  # stopped after the selection's last frame
    with pytest.raises(VideoError, match="damaged or truncated after frame 4, the last selected"):
        read_video(clip, skip=2)
    with pytest.raises(VideoError, match="damaged or truncated after 6 frames"):
        read_video(clip)


def _ffmpeg(*args) -> None:
    import subprocess

    import imageio_ffmpeg

    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", *map(str, args)], check=True)


def test_portrait_phone_clip_is_read_upright_without_warnings(tmp_path, synth_clip, caplog):
    """Phones store a portrait clip as landscape frames plus a display rotation; the frames come back
    turned as a player shows them, and imageio-ffmpeg's size warning about it is not passed on."""
    from gma.video import read_video

    _, clip = synth_clip
    stored = tmp_path / "stored.mp4"
    rotated = tmp_path / "portrait.mp4"
    # A wide strip (192x96) of the clip, so that a turn changes the frame's shape.
    _ffmpeg("-i", clip, "-vf", "crop=192:96:0:48", "-c:v", "libx264", "-pix_fmt", "yuv420p", stored)
    _ffmpeg("-display_rotation", "90", "-i", stored, "-c", "copy", rotated)
    plain, _ = read_video(stored)
    with caplog.at_level(logging.WARNING):
        upright, _ = read_video(rotated)
    assert plain.shape == (10, 96, 192, 3) and upright.shape == (10, 192, 96, 3)
    assert np.array_equal(upright, np.rot90(plain, 1, axes=(1, 2)))  # 90 degrees counter-clockwise, as stored
    assert not [r for r in caplog.records if "frame size" in r.getMessage()]


@pytest.mark.parametrize("transfer, name", [("arib-std-b67", "HLG"), ("smpte2084", "PQ")])
def test_hdr_phone_clip_is_tone_mapped(tmp_path, synth_clip, transfer, name, monkeypatch):
    """Phones record HDR (iPhones HLG, many others PQ). The clip here is the SDR clip turned into 10-bit HDR
    the way BT.2408 places SDR white (203 cd/m²): read back, its frames match the SDR clip's within
    compression noise and the import is told what it was; decoded as if SDR they come out dim and grey."""
    import imageio_ffmpeg

    import gma.data.importers.video as video_io
    from gma.video import read_video

    _, clip = synth_clip
    hdr = tmp_path / f"{name}.mp4"
    _ffmpeg("-i", clip, "-vf", f"zscale=tin=bt709:min=bt709:pin=bt709:t={transfer}:m=bt2020nc:p=bt2020:npl=203,"
            "format=yuv420p10le", "-c:v", "libx265", "-x265-params", "log-level=error", "-color_primaries", "bt2020",
            "-color_trc", transfer, "-colorspace", "bt2020nc", hdr)
    sdr, _ = read_video(clip)
    info: dict = {}
    mapped, _ = read_video(hdr, info=info)
    assert info["hdr"] == name and info["frames_estimate"] == 10
    assert np.abs(mapped.astype(float) - sdr).mean() < 4.0  # measured 1.7 (HLG) and 2.2 (PQ): two lossy encodes
    # A selection is dropped before the tone mapping (ffmpeg's select filter): the same frames.
    selected, idx = read_video(hdr, 1, None, 3)
    assert idx == [1, 4, 7] and np.array_equal(selected, mapped[idx])
    gen = imageio_ffmpeg.read_frames(str(hdr))
    next(gen)
    as_sdr = np.stack([np.frombuffer(f, np.uint8).reshape(sdr.shape[1:]) for f in gen])
    assert np.abs(as_sdr.astype(float) - sdr).mean() > 10.0  # read without the tone mapping: 15.8 and 23.5
    # An ffmpeg without the filters gets one line that says what is missing.
    monkeypatch.setattr(video_io, "TO_SDR", "no_such_filter")
    with pytest.raises(ValueError, match=f"{hdr.name}: an HDR \\({name}\\) video.*cannot tone-map"):
        read_video(hdr)


# -- left/right swaps -------------------------------------------------------------------------------
def _torso(yaw: float) -> np.ndarray:
    """MediaPipe-like world landmarks [33, 3] (camera axes) of a torso facing ``yaw``."""
    p = np.zeros((33, 3))
    left = np.array([np.cos(yaw), 0, np.sin(yaw)])  # yaw 0: the person's left is the camera's +x
    for idx, side, height in ((11, 1, -0.5), (12, -1, -0.5), (23, 1, 0.0), (24, -1, 0.0)):
        p[idx] = side * 0.18 * left + np.array([0, height, 0])
    return p


def test_swaps_resolved_on_a_turn():
    from gma.video.swaps import apply_swaps, facing_yaw, resolve_swaps

    yaws = np.radians(np.arange(0, 181, 20))
    p3 = np.stack([_torso(y) for y in yaws])
    assert np.allclose(np.abs(facing_yaw(p3)), np.abs(np.arctan2(np.sin(yaws), np.cos(yaws))), atol=1e-6)
    # MediaPipe's frontal reading of the back half: labels swapped, depth mirrored.
    truth = yaws > np.pi / 2
    p2 = np.zeros((len(yaws), 33, 3))
    _, seen, _ = apply_swaps(p2, p3, np.zeros((len(yaws), 2, 21, 3)), truth)
    found = np.ones(len(yaws), bool)
    face = yaws < np.radians(60)
    assert (resolve_swaps(seen, found, face) == truth).all()
    assert not resolve_swaps(p3, found, face).any()


def test_no_swaps_when_the_face_detector_barely_works():
    # A full turn read correctly by MediaPipe, at a resolution where the face detector found a face in
    # one frame of 24 (a 256 px synthetic clip did exactly that): frames without a face must not be
    # read as back views, or the last frames of the turn come out mirrored.
    from gma.video.swaps import resolve_swaps

    yaws = np.radians(np.arange(0, 360, 15))
    p3 = np.stack([_torso(y) for y in yaws])
    found = np.ones(len(yaws), bool)
    face = np.zeros(len(yaws), bool)
    face[3] = True
    assert not resolve_swaps(p3, found, face).any()


# -- body fit against exact landmarks ---------------------------------------------------------------
@pytest.mark.slow
def test_fit_recovers_gt_landmarks(synth_clip, rig):
    from gma.video.fit import FitConfig, fit_body
    from gma.video.targets import build_targets

    seq, _ = synth_clip
    gt = _gt_uv(rig, seq)
    T = len(seq)
    tg = build_targets(rig.point_names, np.zeros((T, 33, 3)), np.full((T, 33, 3), np.nan),
                       np.zeros((T, 2, 21, 3)), np.zeros(T, bool))
    # Exact 2D targets for the body points; 3D directions from the truth in camera axes; one frame
    # marked missing to exercise interpolation.
    body = [rig.index(n) for n in BODY_JOINTS]
    tg.uv[:] = torch.as_tensor(gt)
    tg.conf[:, body] = 1.0
    tg.found[:] = True
    tg.scale[:] = 150.0
    tg.conf[4] = 0
    tg.found[4] = False
    pose3d = np.full((T, 33, 3), np.nan)
    K, w2c = seq.cameras.frame(0)
    with torch.no_grad():
        rest = rig.rest(torch.as_tensor(seq.body.arrays["phenotype"]).float())
        pts = rig.points(rig.transforms(torch.as_tensor(seq.body.arrays["pose"]).float(), rest), rest).numpy()
    mp_of = {11: "coco:left_shoulder", 12: "coco:right_shoulder", 23: "coco:left_hip", 24: "coco:right_hip"}
    for t in range(T):
        _, w2c_t = seq.cameras.frame(t)
        for mp_i, name in mp_of.items():
            pose3d[t, mp_i] = w2c_t[:3, :3] @ pts[t, rig.index(name)]
    res = fit_body(rig, tg, pose3d, K, None, FitConfig(iters_root=40, iters_pose=120, iters_shape=0),
                   progress=False)
    assert res.pose.shape == (T, 104, 4, 4) and np.isfinite(res.pose).all()
    assert _joint_error(rig, res.uv, gt) < GT_LANDMARK_PX


def _eye_line(rig, pose: torch.Tensor, rest, w2c: np.ndarray) -> np.ndarray:
    """[T, 3] unit direction from the right eye to the left in camera axes."""
    with torch.no_grad():
        pts = rig.points(rig.transforms(pose, rest), rest).numpy()
    d = pts[:, rig.index("coco:left_eye")] - pts[:, rig.index("coco:right_eye")]
    d = d @ w2c[:3, :3].T
    return d / np.linalg.norm(d, axis=-1, keepdims=True)


def _angle_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """[T] degrees between unit vectors [T, 3]."""
    return np.degrees(np.arccos(np.clip((a * b).sum(-1), -1, 1)))


def test_face_mesh_directions_turn_the_head(synth_clip, rig, anny_body):
    """The body's 2D landmarks say nothing of the head (its points are left out); the face mesh's 3D eye
    line, taken from the same frames with the head turned 0.5 rad, must turn the fitted head."""
    from gma.video.camera import CAMERA_FROM_WORLD
    from gma.video.fit import FitConfig, fit_body
    from gma.video.landmarks import FACE_POINTS
    from gma.video.targets import build_targets

    seq, _ = synth_clip
    T = 2
    pose = torch.as_tensor(seq.body.arrays["pose"][:T]).float()
    rest = rig.rest(torch.as_tensor(seq.body.arrays["phenotype"]).float())
    turned = pose.clone()
    head = anny_body.bone_index("head")
    turn = roma.rotvec_to_rotmat(torch.tensor([0.0, 0.0, 0.5]))
    turned[:, head, :3, :3] = turned[:, head, :3, :3] @ turn
    _, w2c = seq.cameras.frame(0)
    target_line = _eye_line(rig, turned, rest, w2c)
    moved = _angle_deg(_eye_line(rig, pose, rest, w2c), target_line)
    assert (moved > 10).all(), moved  # the turn shows in the eye line
    with torch.no_grad():
        face_pts = rig.points(rig.transforms(turned, rest), rest)[:, [rig.index(n) for n in FACE_POINTS]]
        body_pts = rig.points(rig.transforms(pose, rest), rest).numpy()
    face3d = face_pts.numpy() @ w2c[:3, :3].T * 1000  # any scale: only directions count
    torso = np.full((T, 33, 3), np.nan)  # the torso's world landmarks start the root (as in the test above)
    for mp_i, name in {11: "coco:left_shoulder", 12: "coco:right_shoulder", 23: "coco:left_hip",
                       24: "coco:right_hip"}.items():
        torso[:, mp_i] = body_pts[:, rig.index(name)] @ w2c[:3, :3].T
    gt_uv = torch.as_tensor(_gt_uv(rig, seq)[:T])

    def fitted_eye_error(face):
        tg = build_targets(rig.point_names, np.zeros((T, 33, 3)), np.full((T, 33, 3), np.nan),
                           np.zeros((T, 2, 21, 3)), np.ones(T, bool), face3d=face)
        body = [rig.index(n) for n in BODY_JOINTS if n != "coco:nose"]
        tg.uv[:] = gt_uv
        tg.conf[:, body] = 1.0
        tg.scale[:] = 150.0
        res = fit_body(rig, tg, torso, seq.cameras.frame(0)[0], None,
                       FitConfig(iters_root=20, iters_pose=100, iters_shape=0), progress=False)
        got = _eye_line(rig, torch.as_tensor(res.pose), rest, np.pad(CAMERA_FROM_WORLD, ((0, 1), (0, 1))))
        return _angle_deg(got, target_line)

    with_face, without = fitted_eye_error(face3d), fitted_eye_error(None)
    assert with_face.max() < 5 and without.mean() > 10, (with_face, without)


# -- the whole pipeline (MediaPipe) -----------------------------------------------------------------
def test_pipeline_on_synthetic_clip(tmp_path, synth_clip, rig, anny_body):
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.data import read_sequence
    from gma.video import FitConfig, VideoImportConfig, estimate_sequence

    seq_gt, clip = synth_clip
    cfg = VideoImportConfig(focal=float(seq_gt.cameras.K[0, 0, 0]),
                            fit=FitConfig(iters_root=40, iters_pose=150, iters_shape=6))
    out = tmp_path / "seq"
    seq, report = estimate_sequence(clip, out, config=cfg, progress=False, anny=anny_body)
    assert len(seq) == 10 and seq.body.model == "anny"
    assert read_sequence(out).body.arrays["pose"].shape == (10, 104, 4, 4)
    assert report["detection_rate"] == 1.0 and report["frames_interpolated"] == 0
    assert report["frames_limbs_swapped"] == {"arms": 0, "legs": 0}  # a clean synthetic turn
    # Fitted model points against the truth, both projected into the same image.
    from gma.video.fit import project

    pose = torch.as_tensor(seq.body.arrays["pose"]).float()
    rest = rig.rest(torch.as_tensor(seq.body.arrays["phenotype"]).float())
    with torch.no_grad():
        pts = rig.points(rig.transforms(pose, rest), rest)
    K, w2c = (torch.as_tensor(a).float() for a in seq.cameras.frame(0))
    uv = project(pts, K, w2c[:3, :3], w2c[:3, 3]).numpy()
    err = _joint_error(rig, uv, _gt_uv(rig, seq_gt))
    assert err < PIPELINE_JOINT_PX, f"mean joint error {err:.2f} px"
    assert report["mask_iou_mean"] > PIPELINE_IOU
    saved = json.loads((out / "video_report.json").read_text())
    assert saved["frames_used"] == 10 and (out / "video_contact_sheet.png").is_file()
    # A fixed camera: MediaPipe's masks were checked against the background, and stay close to the truth.
    assert saved["mask_check"]["applied"], saved["mask_check"]
    from gma.video.report import mask_iou

    ious = [mask_iou(seq.mask(t) > 0.5, seq_gt.mask(t) > 0.5) for t in range(10)]
    assert min(ious) > 0.9, ious
    # the fitted body shape is reported by name, the same values as the sequence's phenotype
    named = saved["phenotype_named"]
    assert list(named) == list(anny_body.param_spaces["shape"].labels)
    np.testing.assert_allclose(list(named.values()), seq.body.arrays["phenotype"], atol=1e-4)
    # Resumable: a second run reuses every detection and the fit.
    _, again = estimate_sequence(clip, out, config=cfg, progress=False, anny=anny_body, overwrite=True)
    assert again["frames_detect_reused"] == 10 and again["fit_resumed_from_cache"]
    # --no-mask-check keeps MediaPipe's masks.
    from gma.cli import main

    assert main(["import", "video", str(clip), str(out), "--force", "--no-mask-check", "--focal",
                 str(cfg.focal), "--fit-iters", "40", "150", "6"]) == 0
    plain = json.loads((out / "video_report.json").read_text())
    assert plain["mask_check"] == {"applied": False, "reason": "--no-mask-check"}


def test_camera_file_undistorts_and_scales(tmp_path, synth_clip, anny_body):
    """The synthetic clip seen through a distorting lens, imported with that lens's camera file and
    --downscale 2 (body given, so no fit): the sequence's frames are the undistorted ones (close to the
    clean clip's), and its K is the file's, in GMA's pixel convention, halved."""
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    import cv2
    import imageio.v3 as iio

    from gma.data.importers._common import resize_frame
    from gma.video import VideoImportConfig, estimate_sequence, read_video
    from gma.video.camera import load_intrinsics

    seq_gt, _ = synth_clip
    K = seq_gt.cameras.K[0]
    cam = {"fx": K[0, 0], "fy": K[1, 1], "cx": K[0, 2] - 0.5, "cy": K[1, 2] - 0.5, "k1": -0.5, "k2": 0.2,
           "p1": 0.002, "p2": 0.0}  # moves the person's outline by 2-4 px, the corners by ~13 px
    (tmp_path / "cam.json").write_text(json.dumps(cam))
    intr = load_intrinsics(tmp_path / "cam.json")
    H, W = seq_gt.height, seq_gt.width
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float64)
    und = cv2.undistortPoints(np.stack([xx.ravel(), yy.ravel()], -1)[:, None], intr.opencv_K(),
                              np.asarray(intr.dist), P=intr.opencv_K())
    map_x, map_y = (und[:, 0, i].reshape(H, W).astype(np.float32) for i in (0, 1))
    clean = np.stack([seq_gt.image(i) for i in range(len(seq_gt))])
    lens = np.stack([cv2.remap(f, map_x, map_y, cv2.INTER_LINEAR) for f in clean])
    clip = tmp_path / "lens.mp4"
    iio.imwrite(clip, lens, fps=10, codec="libx264", macro_block_size=16)

    cfg = VideoImportConfig(camera=intr)
    seq, report = estimate_sequence(clip, tmp_path / "seq", config=cfg, body=seq_gt.root / "body.npz", downscale=2,
                                    progress=False, anny=anny_body)
    assert (seq.width, seq.height) == (W // 2, H // 2)
    np.testing.assert_allclose(seq.cameras.K[0], np.diag([0.5, 0.5, 1]) @ K, atol=1e-9)
    assert report["camera"]["undistorted"] and report["camera"]["source"].endswith("cam.json")

    def err(a, b):  # mean absolute difference inside the frame's central 80 %
        m = (slice(H // 20, H // 2 - H // 20), slice(W // 20, W // 2 - W // 20))
        return float(np.abs(a[m].astype(float) - b[m].astype(float)).mean())

    def small(img):
        return resize_frame(img, np.ones(img.shape[:2], np.float32), 2)[0]

    decoded, _ = read_video(clip)  # the distorted frames as the import saw them (mp4 loses a little)
    fixed = np.mean([err(seq.image(i), small(clean[i])) for i in range(len(seq))])
    as_seen = np.mean([err(small(decoded[i]), small(clean[i])) for i in range(len(seq))])
    # what mp4 alone costs (the clean clip's own encoding); two bilinear resamplings add ~0.2 to it
    floor = np.mean([err(small(f), small(clean[i])) for i, f in enumerate(read_video(synth_clip[1])[0])])
    assert fixed - floor < 0.35 * (as_seen - floor), (fixed, as_seen, floor)


def test_no_person_is_a_clear_error(tmp_path, empty_room_clip):
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.video import estimate_sequence

    clip = empty_room_clip
    with pytest.raises(ValueError, match="no person detected"):
        estimate_sequence(clip, tmp_path / "seq", progress=False)


def test_wrong_mask_folder_fails_before_detection(tmp_path, empty_room_clip):
    """--mask-dir with the wrong number of masks, or a --body file that is not there, is refused before any
    frame is detected (nothing is left in OUT.work)."""
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    import imageio.v3 as iio

    from gma.video import estimate_sequence

    masks = tmp_path / "masks"
    masks.mkdir()
    for i in range(3):  # the clip has 4 frames
        iio.imwrite(masks / f"{i:03d}.png", np.zeros((64, 64), np.uint8))
    with pytest.raises(ValueError, match="3 mask images for 4 video frames"):
        estimate_sequence(empty_room_clip, tmp_path / "seq", mask_dir=masks, progress=False)
    with pytest.raises((OSError, ValueError), match="missing_body.npz"):  # the same for --body
        estimate_sequence(empty_room_clip, tmp_path / "seq", body=tmp_path / "missing_body.npz", progress=False)
    assert not (tmp_path / "seq.work" / "detect").exists()


# The iPER clip is for research use only and not shipped: docs/data.md says where to get it.
IPER = Path(os.environ.get("GMA_IPER_CLIP") or Path(__file__).resolve().parents[1] / "data" / "iper_turn_512.gif")


@pytest.mark.slow
@pytest.mark.skipif(not IPER.is_file(), reason=f"{IPER} not present (set GMA_IPER_CLIP; docs/data.md)")
def test_pipeline_on_real_footage(tmp_path, anny_body):
    """iPER: a man turning once in A-pose. Every 6th frame, a short fit: the person is found in every
    frame and the fitted body covers the mask reasonably."""
    pytest.importorskip("mediapipe", reason="the video extra (pip install 'gma[video]') is not installed")
    from gma.video import FitConfig, VideoImportConfig, estimate_sequence

    cfg = VideoImportConfig(skip=6, fit=FitConfig(iters_root=30, iters_pose=100, iters_shape=0))
    seq, report = estimate_sequence(IPER, tmp_path / "seq", config=cfg, progress=False, anny=anny_body)
    assert len(seq) == 9 and report["detection_rate"] == 1.0
    assert report["mask_iou_mean"] > 0.5
    assert report["reprojection_error_px_mean"] < 25.0
