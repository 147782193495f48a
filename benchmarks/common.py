"""Helpers shared by the benchmark scripts: timing medians, machine description, the standard scene."""

from __future__ import annotations

import functools
import os
import platform
import statistics
import subprocess
import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
# The real clip some video benchmarks use: a turn from the iPER dataset, which is for research use only,
# so the repository does not ship it (docs/data.md, "Real footage", says where to get it).
IPER_CLIP_ENV = "GMA_IPER_CLIP"
IPER_CLIP_DEFAULT = REPO / "data" / "iper_turn_512.gif"


def iper_clip() -> Path:
    """Where the iPER turn clip is looked for: ``$GMA_IPER_CLIP``, else ``data/iper_turn_512.gif``."""
    return Path(os.environ.get(IPER_CLIP_ENV) or IPER_CLIP_DEFAULT)


def iper_missing(clip: Path) -> str:
    """The one line a script prints when the clip is absent."""
    return (f"{clip}: not found; the iPER turn clip (research use only) is not shipped: see docs/data.md "
            f"(\"Real footage\") or set {IPER_CLIP_ENV}")


def median_ms(fn, repeats: int = 5, warmup: int = 1) -> tuple[float, list[float]]:
    """Median wall time of ``fn()`` in ms (after ``warmup`` calls), and all samples."""
    for _ in range(warmup):
        fn()
    samples = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        samples.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(samples), samples


def median_dict(dicts: list[dict[str, float]]) -> dict[str, float]:
    keys = sorted({k for d in dicts for k in d})
    return {k: statistics.median(d.get(k, 0.0) for d in dicts) for k in keys}


def machine() -> str:
    """The processor, its cores, the vector width torch's kernels use and the load: torch's peers run
    faster on an AVX-512 processor where lavapipe stays at 256 bits, so ratios differ by machine kind."""
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    return f"{cpu_name()}, {os.cpu_count()} cores{_torch_simd()}, load {load:.2f}"


@functools.lru_cache(maxsize=1)
def cpu_name() -> str:
    """The processor's model name and family (Linux's /proc/cpuinfo), else what the platform says."""
    fields = {}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            key, _, value = line.partition(":")
            fields.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    name = fields.get("model name") or platform.processor() or platform.machine()
    return f"{name} (family {fields['cpu family']})" if "cpu family" in fields else name


def _torch_simd() -> str:
    """", torch AVX512" and the like, where the script has imported torch (importing it here would cost a
    second for scripts that do not)."""
    torch = sys.modules.get("torch")
    return f", torch {torch.backends.cpu.get_cpu_capability()}" if torch else ""


def load_standard_workload():
    """The standard scene's module (``splat_scene.py`` beside this file: ``make_workload``, ``WIDTH``,
    ``HEIGHT``)."""
    import splat_scene

    return splat_scene


def scene_tensors(workload, n: int) -> dict:
    """The standard scene of ``n`` surfels as torch tensors, as peer_compare.py and first_call.py time it:
    ``scales`` GMA's two per surfel, ``scales3`` the peer's 2DGS layout (third scale 0)."""
    import torch

    w = workload.make_workload(n)
    t = {k: torch.from_numpy(w[k]) for k in ("means", "quats", "opacities", "colors", "viewmat", "K")}
    t["scales3"] = torch.from_numpy(w["scales_2d"])
    t["scales"] = t["scales3"][:, :2].contiguous()
    return t


def add_scene_args(ap, reference_count: int, reference_size: int) -> None:
    """The renderer benchmarks' options for the standard scene's sizes and the torch reference comparison
    (render.py, render_backward.py; the smoke tests make them tiny)."""
    from gma.core.args import positive_int

    ap.add_argument("--standard-counts", type=positive_int, nargs="*", default=[20_000, 100_000],
                    help="surfel counts of the standard comparison scene (none: skip it)")
    ap.add_argument("--reference-count", type=positive_int, default=reference_count,
                    help="surfels of the torch reference comparison")
    ap.add_argument("--reference-size", type=positive_int, default=reference_size,
                    help="image size of the torch reference comparison")


def workload_surfels(module, n: int) -> tuple[dict, object]:
    """Standard scene as 2D surfels (third scale dropped) and its camera."""
    import numpy as np

    from gma.core.camera import Camera

    w = module.make_workload(n)
    scene = {"means": w["means"], "quats": w["quats"], "scales": np.ascontiguousarray(w["scales"][:, :2]),
             "opacities": w["opacities"], "colors": w["colors"]}
    cam = Camera(w["viewmat"], w["K"], module.WIDTH, module.HEIGHT)
    return scene, cam


# The render passes that PassTimer names, in order (shader_ab.py, lavapipe_profile.py).
PASSES = ("project", "sort", "scan", "bin", "rasterize", "rasterize_bwd", "project_bwd")


def scene_and_camera(count: int, kind: str = "standard", size: int = 512):
    """``count`` surfels and a camera: the standard scene, or with ``kind="avatar"`` avatar-like surfels
    (small, tangent to a body-shaped surface) at ``size`` pixels."""
    if kind == "avatar":
        from gma.render.scenes import avatar_camera, avatar_like_scene

        return avatar_like_scene(count), avatar_camera(size, size)
    return workload_surfels(load_standard_workload(), count)


def pass_inputs(ctx, scene: dict, cam):
    """A scene's surfels uploaded to the GPU and a fixed random colour gradient of its image (scale 1e-3):
    what the pass-by-pass scripts (shader_ab.py, lavapipe_profile.py) render and backpropagate."""
    import numpy as np

    from gma.render import SurfelBuffers

    surfels = SurfelBuffers.from_arrays(ctx, scene["means"], scene["quats"], scene["scales"], scene["opacities"],
                                        scene["colors"])
    upstream = np.random.default_rng(0).normal(size=(cam.height, cam.width, scene["colors"].shape[1]))
    return surfels, (upstream * 1e-3).astype(np.float32)


class CheckoutWorker:
    """A GMA checkout's code in a worker process: ``script --worker *args`` run with PYTHONPATH=the
    checkout, which prints "ready" once set up and then answers each request line with one line. Lets a
    benchmark time another checkout (``--baseline``) beside this one, turns interleaved, in one run;
    ``env`` adds variables for the worker (e.g. the Vulkan loader's ``VK_DRIVER_FILES``: the same code on
    another driver)."""

    def __init__(self, root: str | Path, script: str | Path, *args: str, env: dict[str, str] | None = None):
        self.root = self.checkout(root)
        env = dict(os.environ, **(env or {}), PYTHONPATH=str(self.root))
        self.proc = subprocess.Popen([sys.executable, str(script), "--worker", *args], cwd=self.root, env=env,
                                     stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        ready = self.proc.stdout.readline().strip()
        if not ready.startswith("ready"):
            raise SystemExit(f"{root}: the worker did not start ({ready!r})")
        self.banner = ready.removeprefix("ready").strip()  # what the worker says of itself (its adapter)

    @staticmethod
    def checkout(root: str | Path) -> Path:
        """``root`` resolved; exits with one line when it is not a GMA checkout (check before slow set-up)."""
        path = Path(root).resolve()
        if not (path / "gma" / "__init__.py").is_file():
            print(f"{root}: not a GMA checkout (no gma/__init__.py)", file=sys.stderr)
            raise SystemExit(2)
        return path

    def ask(self, request: str) -> str:
        self.proc.stdin.write(request + "\n")
        self.proc.stdin.flush()
        return self.proc.stdout.readline()

    def close(self) -> None:
        self.proc.stdin.close()
        self.proc.wait()


def wrong_checkout() -> str | None:
    """In a worker: an error line when ``gma`` was not imported from the checkout on PYTHONPATH, else None."""
    import gma

    root = Path(os.environ["PYTHONPATH"]).resolve()
    if not Path(gma.__file__).resolve().is_relative_to(root):
        return f"error: gma imported from {gma.__file__}, not {root}"
    return None


def parse_env(items: list[str] | None) -> dict[str, str]:
    """``["KEY=VALUE", ...]`` (a benchmark's ``--baseline-env``) as a dict; exits with one line on a bad item."""
    env = {}
    for item in items or []:
        key, sep, value = item.partition("=")
        if not sep or not key:
            print(f"--baseline-env {item!r}: expected KEY=VALUE", file=sys.stderr)
            raise SystemExit(2)
        env[key] = value
    return env
