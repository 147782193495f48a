"""Torch's idle OpenMP workers asleep while GMA renders on a CPU adapter, the gma command's opt-in
(gma/commands/_openmp_workers.py, entered through gma.render.api.around_device_work): they stop spinning,
torch works as before afterwards, and the render is the same."""

import threading
import time
from pathlib import Path

import pytest
import torch
from render_helpers import default_camera, torch_scene

from gma.commands import _openmp_workers as openmp_workers
from gma.commands._openmp_workers import openmp_workers_asleep
from gma.render import rasterize
from gma.render.api import around_device_work

needs_libgomp = pytest.mark.skipif(openmp_workers._library() is None, reason="needs torch on libgomp (Linux)")


@pytest.fixture(autouse=True)
def two_torch_threads():
    """Torch on two threads (as on CI's 2-core machines; in-process fits, eval and the viewer set fewer)."""
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    yield
    torch.set_num_threads(before)


def _other_threads_cpu_ms() -> float:
    """CPU time (ms) of this process's threads other than the calling one (from each thread's schedstat)."""
    me = threading.get_native_id()
    total = 0
    for task in Path("/proc/self/task").iterdir():
        if int(task.name) == me:
            continue
        try:
            total += int((task / "schedstat").read_text().split()[0])
        except (OSError, ValueError):   # a thread that ended meanwhile
            pass
    return total / 1e6


def _others_cpu_after_a_parallel_op(asleep: bool) -> float:
    """Other threads' CPU over 60 ms right after a parallel torch op, the workers asleep or not meanwhile."""
    big = torch.ones(4_000_000)
    big.mul_(1.5)   # large enough for torch to run it on all its threads
    with openmp_workers_asleep(active=asleep) as sleeping:
        start = _other_threads_cpu_ms()
        time.sleep(0.06)
        used = _other_threads_cpu_ms() - start
    assert sleeping == asleep
    return used


@needs_libgomp
def test_the_workers_sleep_instead_of_spinning():
    spinning = min(_others_cpu_after_a_parallel_op(False) for _ in range(3))
    asleep = max(_others_cpu_after_a_parallel_op(True) for _ in range(3))
    # Asleep, the workers take nothing measurable (wake-up and exit: microseconds); allow 1.5 ms for
    # other threads of the test process. Where libgomp spins by default (OMP_WAIT_POLICY unset: ~8 ms
    # on CI's 2-core machines) that spin must be gone.
    assert asleep < 1.5, f"other threads used {asleep:.2f} ms while the workers should sleep"
    if spinning > 4.0:
        assert asleep < spinning / 4


@needs_libgomp
def test_torch_runs_as_before_afterwards_errors_included():
    gomp = openmp_workers._library()
    threads = torch.get_num_threads()
    with openmp_workers_asleep() as sleeping:
        assert sleeping and gomp.omp_in_parallel() == 1
        with openmp_workers_asleep() as nested:   # a region is open: nothing more to do
            assert not nested
        x = torch.arange(1_000_000, dtype=torch.float64)
        assert float(x.sum()) == 999_999 * 1_000_000 / 2   # torch still works inside (on one thread)
    assert gomp.omp_in_parallel() == 0 and torch.get_num_threads() == threads
    with pytest.raises(RuntimeError, match="inside"):
        with openmp_workers_asleep():
            raise RuntimeError("inside")
    assert gomp.omp_in_parallel() == 0
    y = torch.ones(4_000_000).mul_(2.0)
    assert float(y.sum()) == 8_000_000.0


@needs_libgomp
def test_it_does_nothing_where_it_does_not_apply():
    with openmp_workers_asleep(active=False) as sleeping:
        assert not sleeping
    seen = []

    def other_thread():
        with openmp_workers_asleep() as s:   # another thread's pool is not the one that spins
            seen.append(s)

    t = threading.Thread(target=other_thread)
    t.start()
    t.join()
    assert seen == [False]


def _render_step(gpu, scene, cam) -> list[torch.Tensor]:
    params = {k: v.clone().requires_grad_(True) for k, v in scene.items()}
    out = rasterize(params["means"], params["quats"], params["scales"], params["opacities"], params["colors"],
                    torch.from_numpy(cam.viewmat), torch.from_numpy(cam.K), cam.width, cam.height, ctx=gpu)
    (out.color.square().mean() + out.depth.mean()).backward()
    return [out.color.detach(), out.depth.detach()] + [params[k].grad for k in sorted(params)]


@needs_libgomp
def test_the_public_render_is_the_same_either_way(gpu):
    cam = default_camera(96, 80)
    scene = torch_scene(300, seed=4)
    spinning = _render_step(gpu, scene, cam)
    with around_device_work(openmp_workers_asleep):
        asleep = _render_step(gpu, scene, cam)
    assert all(torch.equal(a, b) for a, b in zip(spinning, asleep))
    assert openmp_workers._library().omp_in_parallel() == 0


def test_the_library_enters_only_the_hook_it_is_given(gpu):
    """The public call enters the application's hook around its forward's and its backward's GPU work,
    with whether the adapter is a CPU one, only inside ``around_device_work``, and nothing after it."""
    import contextlib

    cam = default_camera(40, 32)
    scene = torch_scene(50, seed=6)
    entered = []

    @contextlib.contextmanager
    def hook(is_software):
        entered.append(is_software)
        yield

    _render_step(gpu, scene, cam)
    assert entered == []
    with around_device_work(hook):
        _render_step(gpu, scene, cam)
    assert entered == [gpu.is_software] * 2   # the forward and the backward
    _render_step(gpu, scene, cam)
    assert len(entered) == 2
