"""Shared fixtures: one GPU context per session (lavapipe on CI), created lazily."""

from __future__ import annotations

import pytest

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
