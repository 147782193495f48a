"""``synthesize``: write a synthetic ground-truth sequence (``gma synth OUT --seed N``).

Output (the sequence format plus ground truth)::

    OUT/images/, masks/, cameras.json, body.npz (model "anny"), splits.json (train, test_pose, test_view)
    OUT/gt_mesh.npz     faces [F, 3] int32, face_uvs [F, 3, 2], rest_vertices [V, 3] (clothed, canonical
                        A-pose), body_rest_vertices [V, 3] (unclothed), offsets [V, 3],
                        posed_vertices [T, V, 3] (what each frame shows), vertex_labels [V], face_labels [F]
                        (indices into garment_names), phenotype [6]
    OUT/gt_texture.png  the UV texture of that mesh (u right, v up; row 0 is v = 1)
    OUT/synth.json      the configuration, so the sequence can be regenerated

Deterministic: the same configuration gives byte-identical files.
"""

from __future__ import annotations

import dataclasses
import io
import os
from dataclasses import dataclass
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from tqdm import tqdm

from gma.body import load_body
from gma.body.params import SequenceBody
from gma.core.atomic import atomic_write_json
from gma.data.cameras import Cameras
from gma.data.sequence import Sequence, SequenceWriter, prepare_sequence_output
from gma.gpu import get_context
from gma.synth.garments import GARMENTS
from gma.synth.person import make_person
from gma.synth.presets import make_shots

__all__ = ["SynthConfig", "gt_mesh", "synthesize"]


@dataclass
class SynthConfig:
    """What to generate."""

    preset: str = "turn"  # "turn" (PeopleSnapshot-like) or "motion" (X-Humans-like)
    seed: int = 0  # person, clothes, test poses and cameras all follow from it
    width: int = 512  # image size in pixels
    height: int = 512
    train_frames: int = 60  # frames in the "train" split
    test_pose_frames: int = 10  # held-out novel poses
    test_view_frames: int = 10  # held-out novel camera views
    supersample: int = 3  # anti-aliasing: render at this factor and box-filter down
    texture_size: int = 2048  # ground-truth texture resolution (texels per side)
    background: tuple[float, float, float] = (0.5, 0.5, 0.5)  # RGB in [0, 1] behind the person


def synthesize(
    out: str | os.PathLike,
    config: SynthConfig | None = None,
    ctx=None,
    body=None,
    overwrite: bool = False,
    progress: bool = True,
) -> Sequence:
    """Generate the sequence described by ``config`` at ``out`` (atomically) and return it.

    ``ctx`` is the GpuContext (default: ``gma.gpu.get_context()``); ``body`` the Anny body
    (default: ``gma.body.load_body("anny")``), passed in by tests so that it is created once.
    """
    from gma.synth.mesh_raster import MeshRasterizer

    cfg = config or SynthConfig()
    prepare_sequence_output(out, overwrite)  # before the person and the renderer: fail fast
    if cfg.width < 8 or cfg.height < 8:
        raise ValueError(f"image size {cfg.width}x{cfg.height} is too small (at least 8x8)")
    if ctx is None:
        ctx = get_context()
    body = body or load_body("anny")
    person = make_person(cfg.seed, cfg.texture_size, body)
    shots = make_shots(
        cfg.preset,
        body,
        cfg.width,
        cfg.height,
        cfg.train_frames,
        cfg.test_pose_frames,
        cfg.test_view_frames,
        np.random.default_rng([cfg.seed, 2]),
    )
    raster = MeshRasterizer(ctx, person.mesh, cfg.width, cfg.height, supersample=cfg.supersample)
    n = len(shots.pose)
    posed = person.posed_vertices(shots.pose, shots.facial_actions)

    writer = SequenceWriter(out, cfg.width, cfg.height, overwrite=overwrite)
    try:
        for i in tqdm(range(n), desc="synth", unit="frame", disable=not progress, leave=False):
            image, mask = raster.render(posed[i], shots.K, shots.w2c[i], cfg.background)
            writer.add_frame(image, mask)
        writer.set_cameras(Cameras(cfg.width, cfg.height, shots.K[None], shots.w2c))
        arrays = {"pose": shots.pose, "phenotype": person.phenotype, "facial_actions": shots.facial_actions}
        writer.set_body(SequenceBody("anny", arrays))
        writer.set_splits(shots.splits)
        g = person.garments
        with open(writer.path("gt_mesh.npz"), "wb") as f:
            np.savez(
                f,
                faces=person.mesh.faces.astype(np.int32),
                face_uvs=person.mesh.face_uvs,
                rest_vertices=person.rest,
                body_rest_vertices=person.body_rest,
                offsets=person.offsets,
                posed_vertices=posed,
                vertex_labels=g.vertex_labels.astype(np.uint8),
                face_labels=g.face_labels.astype(np.uint8),
                garment_names=np.array(GARMENTS),
                phenotype=person.phenotype,
            )
        buf = io.BytesIO()
        iio.imwrite(buf, person.mesh.texture, extension=".png")
        writer.path("gt_texture.png").write_bytes(buf.getvalue())
        atomic_write_json(writer.path("synth.json"), {**dataclasses.asdict(cfg), "frames": n})
    except BaseException:
        writer.abort()
        raise
    return writer.close()


def gt_mesh(seq_dir: str | os.PathLike) -> dict[str, np.ndarray]:
    """The ground-truth mesh arrays of a synthetic sequence (see the module docstring)."""
    path = Path(seq_dir) / "gt_mesh.npz"
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no ground-truth mesh (only synthetic sequences have one)")
    with np.load(path, allow_pickle=False) as d:
        return {k: d[k] for k in d.files}
