"""Fixtures shared by the viewer tests: an Xvfb display started by the test session, and small sources."""

from __future__ import annotations

import os
import shutil
import subprocess
import time

import pytest


@pytest.fixture(scope="session")
def xvfb_display():
    """Start Xvfb on a free display for the session (skips when Xvfb is not installed)."""
    exe = shutil.which("Xvfb")
    if exe is None:
        pytest.skip("Xvfb is not installed (apt-get install xvfb); the window tests need a display")
    for num in range(151, 200):
        if os.path.exists(f"/tmp/.X{num}-lock") or os.path.exists(f"/tmp/.X11-unix/X{num}"):
            continue
        proc = subprocess.Popen([exe, f":{num}", "-screen", "0", "640x480x24", "-nolisten", "tcp"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(50):
            if os.path.exists(f"/tmp/.X11-unix/X{num}") or proc.poll() is not None:
                break
            time.sleep(0.1)
        if proc.poll() is None:
            break
    else:
        pytest.skip("could not start Xvfb on any display :151-:199")
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("DISPLAY", f":{num}")
        yield f":{num}"
        import glfw

        glfw.terminate()
        proc.terminate()
        proc.wait(timeout=10)


@pytest.fixture(scope="session")
def small_body_source(gpu, anny_body):
    """The Anny body with 3000 placeholder surfels (small enough for lavapipe at 160x120)."""
    from gma.view import BodySource

    return BodySource.placeholder(gpu, anny_body, 3000)


@pytest.fixture(scope="session")
def small_avatar_file(anny_body, tmp_path_factory):
    """A small unfitted avatar (.gma: feature_dim 8, one surfel per face) for the edit tools."""
    from gma.avatar import Avatar
    from gma.avatar.config import AvatarConfig

    path = tmp_path_factory.mktemp("avatar") / "small.gma"
    Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=1), anny_body).save(path)
    return path


@pytest.fixture()
def avatar_state(gpu, anny_body, small_avatar_file, tmp_path):
    """A ViewerState on a fresh copy of the small avatar (edits do not leak between tests)."""
    import shutil

    from gma.view.source import avatar_source
    from viewer.state import ViewerState

    path = tmp_path / "avatar.gma"
    shutil.copyfile(small_avatar_file, path)
    return ViewerState(gpu, avatar_source(gpu, path))


@pytest.fixture(scope="session")
def fitted_avatar_file(gpu, anny_body, tmp_path_factory, tiny_sequence):
    """An avatar fitted with the quick preset's surfel layout (two fine surfels a face, about 55k visible
    from the front: more intersections than the renderer's first capacity guess) for a few steps."""
    from gma.train.config import preset
    from gma.train.trainer import Trainer

    root = tmp_path_factory.mktemp("fitted")
    seq = tiny_sequence(0)
    cfg = preset("quick", resolution=48, stage1_steps=2, stage2_steps=2, checkpoint_every=2, log_every=1,
                 preview_every=0)
    Trainer(cfg, seq, root / "fitted.gma", body=anny_body, ctx=gpu, progress=False).run()
    return root / "fitted.gma"
