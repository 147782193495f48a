"""Shared fixtures: one GPU context per session (lavapipe on CI), created lazily."""

from __future__ import annotations

import pytest

from gma.cli import prepare_environment

# The suite is an application of the library: like the gma command it gives Mesa a runtime folder
# (gma/cli.py), before any test starts wgpu.
prepare_environment()

# Fixtures that hand out a GPU context: a test that takes one is a `gpu` test whether or not it says so.
GPU_FIXTURES = {"gpu", "gpu_no_float_atomics", "small_body_source"}


def pytest_collection_modifyitems(config, items):
    for item in items:
        if GPU_FIXTURES & set(getattr(item, "fixturenames", ())):
            item.add_marker(pytest.mark.gpu)
        if "xvfb_display" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.window)


@pytest.fixture(scope="session")
def gpu():
    """The default GpuContext (skips the test when no adapter exists at all)."""
    from gma.gpu import NoAdapterError, get_context

    try:
        return get_context()
    except NoAdapterError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="session")
def gpu_no_float_atomics():
    """A second context with native float atomics switched off, to test the CAS fallback."""
    from gma.gpu import GpuContext, NoAdapterError

    try:
        return GpuContext.create(disable_features=("shader-float32-atomic", "subgroup"))
    except NoAdapterError as exc:
        pytest.skip(str(exc))


@pytest.fixture(scope="session")
def anny_body():
    """The default Anny body, created once per session (reads anny's cache under $ANNY_CACHE_DIR; the
    very first creation on a machine builds that cache, ~75 s)."""
    pytest.importorskip("anny")
    from gma.body import load_body

    return load_body("anny")


# The tiny synthetic sequence the fit, pose-refinement, batch and viewer tests share.
TINY_SYNTH = dict(width=64, height=64, train_frames=4, test_pose_frames=2, test_view_frames=1, supersample=1,
                  texture_size=256)


@pytest.fixture(scope="session")
def tiny_sequence(tmp_path_factory, gpu, anny_body):
    """A function ``seed -> Sequence``: the tiny synthetic sequence of that seed (TINY_SYNTH: 64 px, 4
    training, 2 novel-pose and 1 novel-view frame), synthesised once per session on first use and shared
    by every module that asks. Read only: copy its folder (``seq.root``) to change anything."""
    from gma.synth.generate import SynthConfig, synthesize

    made = {}

    def get(seed: int = 0):
        if seed not in made:
            made[seed] = synthesize(tmp_path_factory.mktemp("tiny") / f"seed{seed}",
                                    SynthConfig(seed=seed, **TINY_SYNTH), ctx=gpu, body=anny_body, progress=False)
        return made[seed]

    return get


@pytest.fixture(scope="session")
def synth_clip(tmp_path_factory, gpu, anny_body):
    """A 10-frame synthetic turn (192 px) and its mp4 encoding: (Sequence, clip path), shared by the video
    tests. Read only."""
    import imageio.v3 as iio
    import numpy as np

    from gma.synth.generate import SynthConfig, synthesize

    root = tmp_path_factory.mktemp("video")
    cfg = SynthConfig(width=192, height=192, train_frames=10, test_pose_frames=0, test_view_frames=0,
                      supersample=2, texture_size=512)
    seq = synthesize(root / "synth", cfg, ctx=gpu, body=anny_body, progress=False)
    frames = np.stack([seq.image(i) for i in range(len(seq))])
    clip = root / "clip.mp4"
    iio.imwrite(clip, frames, fps=10, codec="libx264", macro_block_size=16)
    return seq, clip


@pytest.fixture()
def empty_room_clip(tmp_path):
    """A 4-frame 64×64 mp4 of grey noise: a video with nobody in it (the video tests' "no person" case)."""
    import imageio.v3 as iio
    import numpy as np

    clip = tmp_path / "empty_room.mp4"
    rng = np.random.default_rng(0)
    frames = np.clip(120 + rng.normal(0, 3, (4, 64, 64, 3)), 0, 255).astype(np.uint8)
    iio.imwrite(clip, frames, fps=5, codec="libx264", macro_block_size=16)
    return clip
