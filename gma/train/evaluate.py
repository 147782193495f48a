"""``gma eval``: render a fitted avatar at the frames of a split and compare with the images — PSNR and
SSIM over the image and inside the person's bounding box (and LPIPS when available), and mask IoU of the
rendered alpha, per frame and averaged, as JSON and a text table, plus side-by-side images
(target | render | error ×4). With ``refine_steps`` the frames' poses are also optimised against their
images with the avatar frozen (test-time pose fitting) and the scores after it reported beside."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from gma.avatar.avatar import Avatar
from gma.avatar.posing import frame_params
from gma.body import load_body
from gma.body.skinning import linear_blend_skinning
from gma.core.atomic import atomic_write_json
from gma.gpu import get_context
from gma.render.image_io import save_png
from gma.synth.generate import gt_mesh
from gma.train.appearance import FrameColour
from gma.train.config import FrameColourConfig
from gma.train.data import load_frames
from gma.train.losses import GeometryTerms, load_lpips
from gma.train.metrics import box_metrics, mask_iou, psnr, ssim
from gma.train.pose_refine import TEST_TIME_MSE, PoseRefineConfig, refine_frozen
from gma.train.regions import RegionMapper, mean_by_region, region_metrics
from gma.train.render_step import render_frame

__all__ = ["EVAL_SPLITS", "evaluate", "evaluate_splits", "fitted_resolution", "format_table", "geometry_metrics"]

# The held-out splits of a synthetic or imported sequence: novel poses and novel views.
EVAL_SPLITS = ("test_pose", "test_view")
WORST = 5  # frames in the "worst" mean
# Test-time pose fitting's resolution for avatars that do not record the one they were fitted at (the
# quick preset's).
FALLBACK_REFINE_RESOLUTION = 192


def evaluate(avatar: Avatar, seq, split: str, out_dir: str | Path | None = None, resolution: int = 512,
             background: float = 0.5, body=None, ctx=None, images: int = 4, use_lpips: bool = True,
             refine_steps: int = 0, refine_resolution: int | None = None, refine: PoseRefineConfig | None = None,
             refine_colour: bool | None = None, progress: bool = False) -> dict:
    """Metrics of ``avatar`` on ``split`` of ``seq`` at ``resolution`` (longest side). Writes
    ``metrics_<split>.json``, ``metrics_<split>.txt`` and up to ``images`` side-by-side PNGs into
    ``out_dir`` when given. Returns {"split", "frames": [{frame, psnr, ssim, psnr_bbox, ssim_bbox,
    mask_iou[, lpips]}], "mean": {...}}, plus "refined": {"steps", "resolution", "coarse_to_fine", "mse", "bones",
    "frames", "mean", "poses"} when ``refine_steps`` > 0: each frame's pose first optimised for that many steps at
    ``refine_resolution`` (None: :func:`fitted_resolution`) against its image with the avatar frozen
    (``refine``: learning rates and prior; coarse to fine, every surfel drawn as the scoring draws them, see
    :func:`gma.train.pose_refine.refine_frozen`), then scored again. With
    ``refine_colour`` (None: when the avatar was fitted with per-frame colour transforms) each frame's colour
    transform (``gma.train.appearance.FrameColour``) is fitted with its pose, and "refined" has "colour".

    The frames' poses are applied to the avatar's own body identity (``avatar.shape``), not the sequence's:
    the avatar's surfels sit on the body it was fitted on. The two are the same for the sequence an avatar
    was fitted on; they differ where an avatar fitted on one estimate of a person is scored on another
    sequence of them (``benchmarks/video_to_avatar.py`` scores avatars fitted on estimated poses and body
    shape against the synthetic ground truth), and ``"identity_delta"`` says by how much."""

    body = body or load_body(avatar.body_name)
    frames = load_frames(seq, body, split, resolution, identity=avatar.shape)
    lp = load_lpips(verbose=True) if use_lpips else None
    with torch.no_grad():
        decoded = avatar.decode()
    rows = _score(decoded, body, frames, None, background, ctx, lp, out_dir, split, images)
    result = {"split": split, "sequence": str(seq.root), "resolution": list(frames.images.shape[1:3]),
              "identity_delta": _identity_delta(avatar, seq, frames.indices[0]), "frames": rows, **_summaries(rows)}
    if refine_steps > 0:
        small = load_frames(seq, body, split, min(refine_resolution or fitted_resolution(avatar), resolution),
                            identity=avatar.shape)
        refine = refine or PoseRefineConfig()
        if refine_colour is None:
            refine_colour = "frame_colour" in avatar.info
        colour = FrameColour(len(small)) if refine_colour else None
        corr = refine_frozen(decoded, body, small, refine_steps, refine, background, ctx, progress=progress,
                             colour=colour, colour_cfg=FrameColourConfig())
        poses = corr.all_poses()
        with torch.no_grad():
            bones = body.bone_transforms({"pose": poses, "shape": frames.shape})
        rows_r = _score(decoded, body, frames, bones, background, ctx, lp, out_dir, split + "_refined", images,
                        colour)
        result["refined"] = {"steps": refine_steps, "resolution": list(small.images.shape[1:3]), "coarse_to_fine": True,
                             "mse": TEST_TIME_MSE, "bones": refine.bones, "frames": rows_r, **_summaries(rows_r),
                             "poses": corr.summary()}
        if colour is not None:
            result["refined"]["colour"] = colour.summary()
    if out_dir is not None:
        out_dir = Path(out_dir)
        atomic_write_json(out_dir / f"metrics_{split}.json", result)
        (out_dir / f"metrics_{split}.txt").write_text(format_table(result) + "\n")
    return result


def fitted_resolution(avatar: Avatar) -> int:
    """The longest image side ``avatar``'s texture was fitted at (``FALLBACK_REFINE_RESOLUTION`` for avatars
    that do not record it): test-time pose fitting renders there. Coarser, a hand or a face is a few pixels
    and its pose is left loose; finer, the avatar shows detail it never learnt (docs/fitting.md)."""
    return int(avatar.info.get("resolution", FALLBACK_REFINE_RESOLUTION))


def _identity_delta(avatar: Avatar, seq, frame: int) -> float:
    """Largest difference between the avatar's body identity and the sequence's (0: the same person)."""
    own = frame_params(seq.body.model, seq.body.frame(frame))["shape"]
    return float((own - avatar.shape).abs().max())  # same size: load_frames checked the identity


def _mean(rows: list[dict]) -> dict:
    return {k: float(np.mean([r[k] for r in rows])) for k in rows[0] if k not in ("frame", "regions")}


def _summaries(rows: list[dict]) -> dict:
    """The means a result carries beside its frames: over all frames, over the ``WORST`` frames by
    person-box PSNR (where an avatar fails, which a mean over many easy frames hides), and by region."""
    worst = sorted(rows, key=lambda r: r["psnr_bbox"])[:WORST]
    return {"mean": _mean(rows), "worst": {"frames": [r["frame"] for r in worst], **_mean(worst)},
            "regions": mean_by_region([r["regions"] for r in rows])}


def _score(decoded, body, frames, bones, background, ctx, lp, out_dir, name: str, images: int,
           colour: FrameColour | None = None) -> list[dict]:
    """Per-frame metrics of ``decoded`` posed with ``bones`` [T, J, 4, 4] (None: the frames' own) and, when
    given, each frame's ``colour`` transform applied; writes up to ``images`` side-by-side PNGs named
    ``<name>_<frame>.png`` into ``out_dir`` when given."""
    rows = []
    keep = set(np.linspace(0, len(frames) - 1, min(images, len(frames))).round().astype(int).tolist())
    mapper = RegionMapper(ctx or get_context(), body)
    with torch.no_grad():
        for t in range(len(frames)):
            frame_bones = frames.bones[t] if bones is None else bones[t]
            out, _ = render_frame(decoded, body, frames, t, background, ctx, cull=False, bones=frame_bones)
            target = frames.target(t, background)
            color = out.color if colour is None else colour.apply(t, out.color, out.alpha, background)
            render = color.clamp(0, 1)
            row = {"frame": frames.indices[t], "psnr": psnr(render, target), "ssim": float(ssim(render, target)),
                   **box_metrics(render, target, frames.masks[t]), "mask_iou": mask_iou(out.alpha, frames.masks[t])}
            posed = linear_blend_skinning(frames.rest[t], body.skin_indices, body.skin_weights, frame_bones)
            regions = mapper.maps(posed, frames.w2c[t], frames.K[t], frames.masks[t])
            row["regions"] = region_metrics(render, target, out.alpha, frames.masks[t], regions)
            if lp is not None:
                row["lpips"] = float(lp(render, target))
            rows.append(row)
            if out_dir is not None and t in keep:
                err = ((render - target).abs() * 4).clamp(0, 1)
                save_png(Path(out_dir) / f"{name}_{frames.indices[t]:06d}.png",
                         torch.cat([target, render, err], 1).numpy())
    return rows


def evaluate_splits(avatar: Avatar, seq, splits=EVAL_SPLITS, out_dir: str | Path | None = None,
                    resolution: int = 512, background: float = 0.5, body=None, ctx=None, images: int = 4,
                    report=print, refine_steps: int = 0, refine_resolution: int | None = None,
                    refine: PoseRefineConfig | None = None, refine_colour: bool | None = None) -> dict:
    """The one evaluation loop of ``gma eval``, ``gma demo`` and the benchmarks: :func:`evaluate` on each
    of ``splits`` that ``seq`` has (``report`` gets each table; ``refine_*``: test-time pose fitting, see
    :func:`evaluate`), then the mesh layer's geometry scores
    when the sequence has a ground-truth mesh (written to ``out_dir/geometry.json``).

    Returns {split: result of :func:`evaluate`} plus "geometry": dict or None."""
    results: dict = {}
    for split in splits:
        if not seq.split(split):
            continue
        results[split] = evaluate(avatar, seq, split, out_dir, resolution, background, body=body, ctx=ctx,
                                  images=images, refine_steps=refine_steps, refine_resolution=refine_resolution,
                                  refine=refine, refine_colour=refine_colour, progress=report is not None)
        if report is not None:
            report(format_table(results[split]))
    geometry = geometry_metrics(avatar, seq)
    if geometry is not None and out_dir is not None:
        atomic_write_json(Path(out_dir) / "geometry.json", geometry)
    results["geometry"] = geometry
    return results


def geometry_metrics(avatar: Avatar, seq) -> dict | None:
    """How well the mesh layer recovered the clothed shape, on sequences with a ground-truth mesh
    (synthetic ones; None otherwise). The avatar's morphed canonical mesh and the ground truth share the
    body's topology, so they compare vertex by vertex, in millimetres:

    mesh_mm: mean distance morphed vertex -> ground-truth clothed vertex; clothed_mm: the same over the
    vertices the clothing moves (> 2 mm); body_mm / body_clothed_mm: the same for the unmorphed body
    (where the mesh layer started); roughness_mm: RMS of the umbrella Laplacian of the morph (a noisy
    mesh layer scores high); the ground truth's is ``gt_roughness_mm``."""
    try:
        truth = gt_mesh(seq.root)
    except FileNotFoundError:
        return None
    gt, gt_offsets = torch.from_numpy(truth["rest_vertices"]).float(), torch.from_numpy(truth["offsets"]).float()
    rest = avatar.rest_vertices.float()
    if gt.shape != rest.shape:
        raise ValueError(f"{seq.root}: ground-truth mesh has {gt.shape[0]} vertices, the avatar's body "
                         f"{rest.shape[0]}")
    offsets = avatar.decode().vertex_offsets
    clothed = gt_offsets.norm(dim=1) > 0.002
    err, base = (rest + offsets - gt).norm(dim=1), (rest - gt).norm(dim=1)
    geo = GeometryTerms(avatar.model.faces, rest.shape[0])  # its laplacian() is the mean squared norm

    def rms_laplacian_mm(x):
        return float(geo.laplacian(x).sqrt()) * 1000

    return {"mesh_mm": float(err.mean()) * 1000, "clothed_mm": float(err[clothed].mean()) * 1000,
            "body_mm": float(base.mean()) * 1000, "body_clothed_mm": float(base[clothed].mean()) * 1000,
            "roughness_mm": rms_laplacian_mm(offsets), "gt_roughness_mm": rms_laplacian_mm(gt_offsets)}


def format_table(result: dict) -> str:
    """A plain-text table: one row per frame, then the mean; after test-time pose fitting, the same
    table of the refined scores below and a line of mean differences."""
    lines = [f"split {result['split']} ({len(result['frames'])} frames, {result['resolution'][1]}x"
             f"{result['resolution'][0]} px)"] + _rows(result)
    if result.get("identity_delta", 0.0) > 1e-6:
        lines.insert(1, f"(posed with the avatar's own body identity; the sequence's differs by up to "
                        f"{result['identity_delta']:.3f})")
    ref = result.get("refined")
    if ref is not None:
        lines.append(f"after test-time pose fitting ({ref['steps']} steps per frame at {ref['resolution'][1]}x"
                     f"{ref['resolution'][0]} px, avatar frozen; mean correction {ref['poses']['mean_bone_deg']:.1f} "
                     f"deg per bone, root {ref['poses']['mean_root_deg']:.1f} deg / "
                     f"{ref['poses']['mean_root_shift_cm']:.1f} cm)")
        lines += _rows(ref)
        lines.append("  gain  " + "  ".join(_fmt(k, ref["mean"][k] - result["mean"][k]) for k in result["mean"]))
    return "\n".join(lines)


def _fmt(key: str, value: float) -> str:
    return f"{value:9.2f}" if key.startswith("psnr") else f"{value:9.4f}"


def _rows(result: dict) -> list[str]:
    keys = list(result["mean"])
    lines = ["frame   " + "  ".join(f"{k:>9}" for k in keys)]
    for r in result["frames"]:
        lines.append(f"{r['frame']:>6}  " + "  ".join(_fmt(k, r[k]) for k in keys))
    lines.append("  mean  " + "  ".join(_fmt(k, result["mean"][k]) for k in keys))
    if len(result["frames"]) > WORST:
        lines.append(f"worst {WORST} " + "  ".join(_fmt(k, result["worst"][k]) for k in keys))
    return lines + _region_rows(result["regions"])


def _region_rows(regions: dict) -> list[str]:
    """Per region: PSNR and SSIM over its pixels, its share of the squared error, mean rendered opacity and
    coverage of the soft mask inside the person's mask there (gma.train.regions)."""
    lines = ["region      psnr       ssim      error    opacity   coverage  frames"]
    for name, r in regions.items():
        cells = ["   absent" if r[k] is None else _fmt(k, r[k])
                 for k in ("psnr", "ssim", "error", "opacity", "coverage")]
        lines.append(f"{name:>6}  " + "  ".join(cells) + f"  {r['frames']:>6}")
    return lines
