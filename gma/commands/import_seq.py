"""``gma import FORMAT SRC OUT``: convert a public dataset layout or a video into a GMA sequence."""

from __future__ import annotations

import argparse
from pathlib import Path

from gma.core.args import non_negative_int, positive_float, positive_int
from gma.core.errors import InputError, MissingFileError


def _common(p: argparse.ArgumentParser, src_help: str) -> None:
    p.add_argument("src", help=src_help)
    p.add_argument("out", help="output sequence directory (written atomically)")
    p.add_argument("--downscale", type=positive_int, default=1, help="shrink images by this integer factor")
    p.add_argument("--force", action="store_true", help="replace OUT if it is a sequence (never another folder)")


def _range(p: argparse.ArgumentParser) -> None:
    p.add_argument("--start", type=non_negative_int, default=0, help="first source frame")
    p.add_argument("--end", type=positive_int, default=None, help="stop before this source frame")
    p.add_argument("--skip", type=positive_int, default=1, help="keep every N-th frame")


def _run(args: argparse.Namespace) -> int:
    if args.format == "motion":
        return _import_motion(args)
    from gma.data import importers
    from gma.data.sequence import prepare_sequence_output

    source = Path(args.src)
    if not source.exists():
        raise MissingFileError(f"{source}: not found")
    prepare_sequence_output(args.out, args.force)  # before reading or detecting anything

    kw = {"downscale": args.downscale, "overwrite": args.force}
    if args.format == "peoplesnapshot":
        seq = importers.import_peoplesnapshot(
            args.src,
            args.out,
            poses=args.poses,
            start=args.start,
            end=args.end,
            skip=args.skip,
            test_start=args.test_start,
            gender=args.gender,
            smpl_dir=args.smpl_dir,
            **kw,
        )
    elif args.format == "xhumans":
        seq = importers.import_xhumans(
            args.src, args.out, gender=args.gender, smplx_dir=args.smplx_dir, skip=args.skip, **kw
        )
    elif args.format == "zjumocap":
        views = None if args.test_views is None else [int(v) for v in args.test_views.split(",") if v]
        seq = importers.import_zjumocap(
            args.src,
            args.out,
            view=args.view,
            test_views=views,
            test_every=args.test_every,
            start=args.start,
            end=args.end,
            skip=args.skip,
            params_dir=args.params,
            smpl_dir=args.smpl_dir,
            **kw,
        )
    elif args.body is None or args.camera is None or not _sequence_cameras(args.camera):
        return _estimate_video(args, kw)
    else:
        seq = importers.import_video(
            args.src,
            args.out,
            body=args.body,
            camera=args.camera,
            alpha=args.alpha,
            mask_video=args.mask_video,
            mask_dir=args.mask_dir,
            start=args.start,
            end=args.end,
            skip=args.skip,
            model_dir=args.model_dir,
            **kw,
        )
    counts = ", ".join(f"{k} {len(v)}" for k, v in seq.splits.items())
    print(
        f"wrote {seq.root}: {len(seq)} frames at {seq.width}x{seq.height}, body {seq.body.model} ({counts})"
    )
    return 0


def _sequence_cameras(path: str) -> bool:
    """Whether ``--camera`` names a sequence-format ``cameras.json`` (with ``w2c``) rather than a file of
    intrinsics; a file that is neither is reported by the loader of intrinsics."""
    import json

    try:
        raw = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(raw, dict) and "w2c" in raw


def _camera_intrinsics(args: argparse.Namespace):
    """``--camera`` as intrinsics (``gma.video.camera.load_intrinsics``), or None; refuses it with --focal."""
    if args.camera is None:
        return None
    from gma.video.camera import load_intrinsics

    if _sequence_cameras(args.camera):
        raise InputError(f"{args.camera}: a sequence's cameras.json (with w2c) needs --body; to estimate the body "
                         "give a camera file of intrinsics (fx, fy, cx, cy, optional k1, k2, p1, p2, k3)")
    if args.focal is not None:
        raise InputError(f"{args.camera}: --focal and --camera both give the focal length; put it in the camera "
                         "file (fx, fy) or drop --camera")
    return load_intrinsics(args.camera)


def _estimate_video(args: argparse.Namespace, kw: dict) -> int:
    """Masks and body from the video itself (gma.video, needs gma[video]); the camera from --camera
    (intrinsics), --focal or the default."""
    from gma.video import FitConfig, VideoImportConfig, estimate_sequence

    if args.alpha or args.mask_video is not None:
        raise ValueError("--alpha/--mask-video need --body and a sequence's cameras.json (--camera); without them "
                         "give --mask-dir or no mask source (MediaPipe estimates the masks)")
    camera = _camera_intrinsics(args)
    fit = FitConfig(iters_root=args.fit_iters[0], iters_pose=args.fit_iters[1], iters_shape=args.fit_iters[2],
                    smooth_frames=args.smooth_frames)
    cfg = VideoImportConfig(focal=args.focal, camera=camera, start=args.start, end=args.end, skip=args.skip,
                            check_masks=not args.no_mask_check, tracking=not args.per_frame, fit=fit)
    seq, report = estimate_sequence(args.src, args.out, config=cfg, mask_dir=args.mask_dir, body=args.body, **kw)
    err = report.get("reprojection_error_px_mean")
    print(f"wrote {seq.root}: {len(seq)} frames at {seq.width}x{seq.height}, body anny; person detected in "
          f"{report['frames_detected']}/{report['frames_used']} frames ({report['frames_interpolated']} "
          f"interpolated), mask IoU of the fitted body {report['mask_iou_mean']:.3f}"
          + ("" if err is None else f", reprojection error {err:.1f} px"))
    if "phenotype_named" in report:
        print("body shape (Anny phenotype, 0-1, 0.5 = average): "
              + ", ".join(f"{k} {v:.2f}" for k, v in report["phenotype_named"].items()))
    if report.get("hdr"):
        print(f"HDR video ({report['hdr']}): frames tone-mapped to SDR (the HDR reference white becomes white)")
    check = report.get("mask_check", {})
    if check.get("applied"):
        print(f"masks checked against the background seen in other frames: {100 * check['person_area_added']:.2f} % "
              f"of the person's area added, {100 * check['person_area_removed']:.2f} % removed")
    elif args.mask_dir is None and "reason" in check:
        print(f"masks left as MediaPipe estimated them: {check['reason']}")
    print(f"report: {seq.root / 'video_report.json'}; overlays: {seq.root / 'video_contact_sheet.png'}")
    return 0


def _import_motion(args: argparse.Namespace) -> int:
    """A motion file (BVH, AMASS / SMPL-X npz, an Anny motion) retargeted, or a video's motion fitted."""
    from gma.core.outputs import prepare_output_file

    source, out = Path(args.src), Path(args.out)
    if not source.exists():
        raise MissingFileError(f"{source}: not found")
    if out.suffix.lower() != ".npz":
        raise InputError(f"{out}: a motion is written as .npz")
    if source.resolve() == out.resolve():
        raise InputError(f"{out}: the output would replace the input")
    prepare_output_file(out, args.force)
    if source.suffix.lower() in (".bvh", ".npz"):
        from gma.body.motion_files import load_motion_file, save_motion

        motion = load_motion_file(source, fps=args.fps, up=args.up)
        save_motion(out, motion)
        print(f"wrote {out}: {len(motion)} frames at {motion.fps:g} fps, retargeted to Anny from {source}")
        return 0
    from gma.body.motion_files import resample, save_motion
    from gma.video import FitConfig, VideoImportConfig
    from gma.video.motion import estimate_motion

    fit = FitConfig(iters_root=args.fit_iters[0], iters_pose=args.fit_iters[1], iters_shape=args.fit_iters[2],
                    smooth_frames=args.smooth_frames)
    cfg = VideoImportConfig(focal=args.focal, camera=_camera_intrinsics(args), start=args.start, end=args.end,
                            skip=args.skip, tracking=not args.per_frame, fit=fit)
    motion, report = estimate_motion(source, out, config=cfg, overwrite=args.force, feet=args.feet)
    if args.fps is not None and abs(args.fps - motion.fps) > 1e-6:
        motion.pose = resample(motion.pose, motion.fps, args.fps)
        motion.expression = motion.expression.new_zeros(len(motion.pose), 52)
        motion.fps = args.fps
        save_motion(out, motion)
    err = report["reprojection_error_px_mean"]
    print(f"wrote {out}: {len(motion)} frames at {motion.fps:g} fps; person detected in "
          f"{report['frames_detected']}/{report['frames_used']} frames ({report['frames_interpolated']} "
          "interpolated)" + ("" if err is None else f", reprojection error {err:.1f} px"))
    return 0


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "import",
        help="import a dataset (PeopleSnapshot, X-Humans, ZJU-MoCap) or a video",
        description=__doc__,
    )
    fmt = p.add_subparsers(dest="format", metavar="FORMAT", required=True)
    _register_datasets(fmt)
    _register_video(fmt)
    _register_motion(fmt)
    p.set_defaults(func=_run)


def _register_datasets(fmt) -> None:
    """The dataset formats: PeopleSnapshot, X-Humans, ZJU-MoCap."""
    ps = fmt.add_parser("peoplesnapshot", help="PeopleSnapshot in InstantAvatar's layout (SMPL)")
    _common(ps, "subject folder with cameras.npz, images/, masks/, poses.npz")
    _range(ps)
    ps.add_argument(
        "--poses", default="poses.npz", help="pose file inside SRC (e.g. poses/anim_nerf_train.npz)"
    )
    ps.add_argument(
        "--test-start", type=int, default=None, help="source frames from here on form the test split"
    )
    ps.add_argument("--gender", choices=("neutral", "male", "female"), default=None)
    ps.add_argument("--smpl-dir", default=None, help="folder with the SMPL model files (or $GMA_SMPL_DIR)")

    xh = fmt.add_parser("xhumans", help="X-Humans take or subject folder (SMPL-X)")
    _common(xh, "a take folder (render/, SMPLX/) or a subject folder (train/Take*, test/Take*)")
    xh.add_argument("--skip", type=positive_int, default=1, help="keep every N-th frame")
    xh.add_argument("--gender", choices=("neutral", "male", "female"), default=None)
    xh.add_argument(
        "--smplx-dir", default=None, help="folder with the SMPL-X model files (or $GMA_SMPLX_DIR)"
    )

    zj = fmt.add_parser("zjumocap", help="ZJU-MoCap subject (annots.npy, params/, mask/) (SMPL)")
    _common(zj, "subject folder, e.g. CoreView_377")
    _range(zj)
    zj.add_argument("--view", type=int, default=0, help="camera used for training (monocular)")
    zj.add_argument("--test-views", default=None, help="comma-separated cameras for the test_view split")
    zj.add_argument("--test-every", type=int, default=30, help="test-view frames every N source frames")
    zj.add_argument("--params", default="params", help="parameter folder (params or new_params)")
    zj.add_argument("--smpl-dir", default=None, help="folder with the SMPL model files (or $GMA_SMPL_DIR)")


def _register_video(fmt) -> None:
    vd = fmt.add_parser(
        "video", help="a video: masks, camera and Anny body estimated (gma[video]) or supplied by the user",
        description="Without --body, MediaPipe (pip install 'gma[video]') finds the person's mask and "
        "landmarks in every frame and Anny is fitted to them. The camera is static with no zoom; its "
        "intrinsics come from --camera FILE (a JSON of fx, fy, cx, cy in pixels of the original video as "
        "OpenCV's calibration writes them, optional distortion k1, k2, p1, p2, k3: frames are then "
        "undistorted), or else square pixels, no distortion, principal point at the image centre and focal "
        "length --focal or the image's longer side. Resumable work is kept in OUT.work/; the report and a "
        "contact sheet of overlays land in OUT (video_report.json, video_contact_sheet.png).",
    )
    _common(vd, "video file (anything ffmpeg reads)")
    _range(vd)
    vd.add_argument("--body", default=None, help="body.npz in the sequence format (all or selected frames); "
                    "default: fitted to the video")
    vd.add_argument("--camera", default=None, help="the camera's intrinsics: JSON {fx, fy, cx, cy[, k1, k2, p1, "
                    "p2, k3][, width, height]} in pixels of the original video (OpenCV convention); with --body, "
                    "also a sequence's cameras.json. Default: a static camera from --focal")
    vd.add_argument("--focal", type=positive_float, default=None, help="focal length in pixels when estimating "
                    "without --camera (default: the longer image side)")
    vd.add_argument("--fit-iters", type=positive_int, nargs=3, default=[60, 200, 150],
                    metavar=("ROOT", "POSE", "SHAPE"),
                    help="body fit steps per stage (root only; all bones; bones + phenotype + silhouette)")
    _smoothing(vd)
    masks = vd.add_mutually_exclusive_group(required=False)
    masks.add_argument("--alpha", action="store_true", help="masks from the video's alpha channel")
    masks.add_argument("--mask-video", default=None, help="a video of masks, one per frame")
    masks.add_argument("--mask-dir", default=None, help="a folder of mask images, one per frame")
    vd.add_argument("--model-dir", default=None, help="SMPL/SMPL-X model folder when body.npz uses them")
    vd.add_argument("--no-mask-check", action="store_true", help="keep MediaPipe's masks as they are (by default "
                    "they are checked against the background seen in other frames, for a fixed camera: holes in "
                    "clothing filled, halos over the background removed; a moving camera is detected and skipped)")


def _smoothing(parser) -> None:
    parser.add_argument("--smooth-frames", type=non_negative_int, default=0, metavar="N",
                        help="video: smooth the landmarks over N frames either side before the body fit, without "
                             "lag (a quadratic over the window; default 0: as detected). For --per-frame clips")
    parser.add_argument("--per-frame", action="store_true",
                        help="video: MediaPipe detects every frame on its own instead of tracking the person "
                             "(its tracking filter lags a fast turn: for clips sampled sparsely in time)")


def _register_motion(fmt) -> None:
    mo = fmt.add_parser(
        "motion", help="a motion for Anny from a BVH, an AMASS / SMPL-X .npz, or a video (gma[video])",
        description="Writes an Anny motion (.npz: local-ref bone transforms, phenotype, fps) that gma render "
        "--motion, gma export --motion and the viewer play. BVH (CMU-style joint names) and AMASS / SMPL-X npz "
        "(poses, trans, mocap_framerate) are retargeted (joint table in gma/body/retarget.py); a video goes "
        "through the body fit of gma import video (MediaPipe landmarks; no masks or images are written).",
    )
    mo.add_argument("src", help=".bvh, AMASS/SMPL-X .npz, or a video file")
    mo.add_argument("out", help="output motion .npz")
    mo.add_argument("--fps", type=positive_float, default=None, help="resample to this frame rate")
    mo.add_argument("--up", choices=("y", "z"), default=None,
                    help="SMPL-X npz: the world's up axis (default: z for AMASS files, else y)")
    mo.add_argument("--force", action="store_true", help="overwrite OUT")
    _range(mo)
    mo.add_argument("--focal", type=positive_float, default=None, help="video: focal length in pixels")
    mo.add_argument("--camera", default=None, help="video: the camera's intrinsics, as for gma import video")
    mo.add_argument("--feet", choices=("frame", "clip"), default="frame",
                    help="video: a foot on the floor in every frame (default; steadies the root) or only at the "
                         "clip's lowest point (keeps jumps)")
    mo.add_argument("--fit-iters", type=positive_int, nargs=3, default=[60, 200, 60], metavar=("ROOT", "POSE", "SHAPE"),
                    help="video: body fit steps per stage")
    _smoothing(mo)
