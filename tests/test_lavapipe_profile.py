"""benchmarks/lavapipe_profile.py's bookkeeping: perf's lines parsed, samples placed in the pass that ran at
their instant, and JIT code told apart as one pass's own or shared by passes. (Its smoke run in
test_benchmarks.py runs the whole script, with perf where the machine has it.)"""

from __future__ import annotations

import importlib.util
import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="module")
def profile():
    sys.path.insert(0, str(BENCH))
    try:
        spec = importlib.util.spec_from_file_location("lavapipe_profile", BENCH / "lavapipe_profile.py")
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        yield module
    finally:
        sys.path.remove(str(BENCH))


def test_perf_lines_parse_to_nanoseconds_addresses_and_objects(profile):
    text = "\n".join([
        " 48473.567516123:      7f9569a091ef (/tmp/perf-29579.map)",
        " 48473.5675162:      7f95940b6a9a (/usr/lib/x86_64-linux-gnu/libc.so.6)",
        "garbage line",
        " 12.000000001:  zz (x)",   # not an address: skipped
    ])
    assert profile.parse_samples(text) == [
        (48473_567516123, 0x7F9569A091EF, "/tmp/perf-29579.map"),
        (48473_567516200, 0x7F95940B6A9A, "/usr/lib/x86_64-linux-gnu/libc.so.6"),
    ]


def test_samples_land_in_their_pass_and_shared_code_is_told_apart(profile):
    jit, libc = "[unknown]", "/usr/lib/x86_64-linux-gnu/libc.so.6"
    own_a, own_b, shared = 0x10000, 0x20000, 0x30000   # 256-byte windows apart
    intervals = [("rasterize", 100, 200), ("project_bwd", 300, 400)]
    samples = [
        (150, own_a + 4, jit), (160, own_a + 8, jit), (170, shared + 1, jit), (180, 0x5000, libc),
        (350, own_b, jit), (360, shared + 2, jit),
        (250, own_a, jit),      # between the passes: the host's or an untimed copy's
        (500, 0x6000, "/usr/lib/python3.11.so"),
    ]
    table, windows = profile.attribute(samples, intervals)
    assert table["rasterize"] == {"shader": 2, "shared JIT": 1, "libc": 1}
    assert table["project_bwd"] == {"shader": 1, "shared JIT": 1}
    assert table[profile.OUTSIDE] == {"shader": 1, "other": 1}
    assert windows[shared >> profile.WINDOW_BITS] == {"rasterize": 1, "project_bwd": 1}


@pytest.mark.parametrize("dso, kind", [("", "jit"), ("[unknown]", "jit"), ("/tmp/perf-1.map", "jit"),
                                       ("/usr/lib/x86_64-linux-gnu/libc.so.6", "libc"),
                                       ("/root/.cache/gma/lavapipe/x/libvulkan_lvp.so", "driver"),
                                       ("[kernel.kallsyms]", "kernel"), ("/usr/lib/libpython3.11.so", "other")])
def test_objects_are_classified(profile, dso, kind):
    assert profile.kind_of(dso) == kind


@pytest.mark.parametrize("args, says", [(["--seconds", "0"], "--seconds"), (["--seconds", "nan"], "--seconds"),
                                        (["--count", "0"], "--count"), (["--size", "8"], "--size"),
                                        (["--frequency", "100000"], "--frequency")])
def test_bad_arguments_get_one_line_and_exit_2(args, says):
    done = subprocess.run([sys.executable, str(BENCH / "lavapipe_profile.py"), *args], capture_output=True,
                          text=True, timeout=120, cwd=BENCH.parent)
    assert done.returncode == 2, done.stderr
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and says in lines[0], done.stderr
    assert "adapter:" not in done.stdout   # refused before any GPU work
