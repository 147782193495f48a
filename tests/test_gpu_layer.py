"""The GPU layer: adapter choice, WGSL loader (includes, defines, conditionals, error report), cached
constants and read-backs."""

from __future__ import annotations

import numpy as np
import pytest
import wgpu

from gma.gpu import ShaderCompileError, ShaderLibrary, context
from gma.gpu.adapter import NoAdapterError, select_adapter
from gma.gpu.context import STORAGE


def write(root, name, text):
    path = root / name
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_includes_defines_and_conditionals(tmp_path):
    write(tmp_path, "common/a.wgsl", "const A: u32 = 1u;\n")
    write(tmp_path, "common/b.wgsl", '#include "common/a.wgsl"\nconst B: u32 = A + 1u;\n')
    write(tmp_path, "main.wgsl", '#include "common/a.wgsl"\n#include "common/b.wgsl"\n'
                                 "#if FAST\nconst MODE: u32 = 1u;\n#else\nconst MODE: u32 = 2u;\n#endif\n"
                                 "#if !FAST\nconst SLOW: bool = true;\n#endif\nenable f16;\n")
    lib = ShaderLibrary(tmp_path)
    src = lib.source("main.wgsl", {"FAST": True, "N": 4, "SCALE": 0.5, "NEG": -3})
    lines = src.splitlines()
    assert lines[0] == "enable f16;", "directives are hoisted above everything"
    assert "const FAST: bool = true;" in lines and "const N: u32 = 4u;" in lines
    assert "const SCALE: f32 = 0.5;" in lines and "const NEG: i32 = -3i;" in lines
    assert src.count("const A: u32 = 1u;") == 1, "an include is inlined once"
    assert "const MODE: u32 = 1u;" in src and "MODE: u32 = 2u" not in src and "SLOW" not in src
    assert "const SLOW: bool = true;" in lib.source("main.wgsl", {"FAST": False})


def test_loader_errors(tmp_path):
    write(tmp_path, "cycle_a.wgsl", '#include "cycle_b.wgsl"\n')
    write(tmp_path, "cycle_b.wgsl", '#include "cycle_a.wgsl"\n')
    write(tmp_path, "unclosed.wgsl", "#if X\nconst Y: u32 = 1u;\n")
    lib = ShaderLibrary(tmp_path)
    with pytest.raises(ValueError, match="include cycle"):
        lib.source("cycle_a.wgsl")
    with pytest.raises(ValueError, match="#if without #endif"):
        lib.source("unclosed.wgsl")
    with pytest.raises(FileNotFoundError, match="missing.wgsl"):
        lib.source("missing.wgsl")


@pytest.mark.gpu
def test_compile_error_prints_numbered_source(gpu, tmp_path):
    write(tmp_path, "bad.wgsl", "@compute @workgroup_size(1)\nfn main() {\n    let x: u32 = undefined_thing;\n}\n")
    with pytest.raises(ShaderCompileError) as info:
        ShaderLibrary(tmp_path).module(gpu.device, "bad.wgsl")
    text = str(info.value)
    assert "bad.wgsl" in text and "   4 |     let x: u32 = undefined_thing;" in text


@pytest.mark.gpu
def test_pipeline_cache_reuses_pipelines(gpu):
    a = gpu.compute_pipeline("sort/radix_count.wgsl", {"SHIFT": 4, "SORT_WG": 16})
    assert gpu.compute_pipeline("sort/radix_count.wgsl", {"SHIFT": 4, "SORT_WG": 16}) is a
    assert gpu.compute_pipeline("sort/radix_count.wgsl", {"SHIFT": 8, "SORT_WG": 16}) is not a
    assert gpu.compute_pipeline("sort/radix_count.wgsl", {"SHIFT": 4, "SORT_WG": 128}) is not a


def test_adapter_preference_errors(monkeypatch):
    with pytest.raises(NoAdapterError, match="mesa-vulkan-drivers"):
        select_adapter("no-such-adapter-name-xyz")


@pytest.mark.gpu
def test_context_reports_features(gpu):
    assert gpu.name
    assert isinstance(gpu.has_float_atomics, bool)
    if gpu.has_subgroups:
        assert gpu.subgroup_size in (4, 8, 16, 32, 64, 128)


@pytest.mark.gpu
def test_oversized_storage_buffer_is_a_clear_error(gpu):
    with pytest.raises(MemoryError, match="'too_big'.*storage binding limit"):
        gpu.buffer(gpu.max_binding_bytes + 4, "too_big")


@pytest.mark.gpu
def test_workspace_reuses_and_grows(gpu):
    from gma.gpu.workspace import Workspace

    ws = Workspace(gpu)
    a = ws.get("scratch", 100)
    assert ws.get("scratch", 64) is a, "a smaller request reuses the buffer"
    b = ws.get("scratch", 1000)
    assert b is not a and b.size >= 1000
    assert ws.nbytes == b.size


def test_constants_are_shared_per_value_and_usage(gpu):
    a = gpu.constant(np.array([3, 0, 0, 0], np.uint32), "a")
    assert gpu.constant(np.array([3, 0, 0, 0], np.uint32), "again") is a
    assert gpu.constant(np.array([4, 0, 0, 0], np.uint32), "other value") is not a
    assert gpu.constant(np.array([3, 0, 0, 0], np.uint32), "other usage", STORAGE | wgpu.BufferUsage.UNIFORM) is not a
    np.testing.assert_array_equal(gpu.read(a, np.uint32), [3, 0, 0, 0])
    with pytest.raises(ValueError, match="4 KiB"):
        gpu.constant(np.zeros(1025, np.float32), "too large")


def test_large_reads_copied_on_two_threads_are_exact(gpu):
    rng = np.random.default_rng(2)
    big = rng.integers(0, 2**32, size=(context.PARALLEL_COPY_BYTES + 12_345) // 4, dtype=np.uint32)
    small = rng.normal(size=777).astype(np.float32)
    got_big, got_small = gpu.read_many([(gpu.upload(big, "big"), np.uint32, big.size),
                                        (gpu.upload(small, "small"), np.float32, small.size)])
    np.testing.assert_array_equal(got_big, big)
    np.testing.assert_array_equal(got_small, small)
