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
