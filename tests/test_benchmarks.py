"""Every benchmark script runs end to end in smoke mode (tiny sizes, a few steps), so none rots between
the runs that produce the figures. Figures printed here mean nothing; the scripts' defaults give them.

A new script in benchmarks/ needs a row in SMOKE (tests fail until it has one). Most of a smoke run is
starting Python, torch, the body model and the GPU device, so the scripts share processes: two groups run
at once (SMOKE_JOBS), each running its scripts one after another in one process (tests/smoke_runner.py),
started when the first of these tests asks; the few that need a process of their own (OWN_PROCESS) run
alone."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BENCH = REPO / "benchmarks"
# Modules the scripts import, not scripts:
HELPERS = {"common.py", "fit_helpers.py", "web_browser.py", "splat_scene.py", "peer_gsplat.py"}

# script -> arguments that make it small; {tmp} is a fresh folder for its outputs, {repo} this checkout.
# A string: skip, with why.
SMOKE: dict[str, list[str] | str] = {
    "render.py": ["--repeats", "1", "--sizes", "64", "--counts", "500", "--standard-counts", "500",
                  "--reference-count", "300", "--reference-size", "32"],
    "render_backward.py": ["--repeats", "1", "--counts", "500", "--standard-counts", "500",
                           "--reference-count", "300", "--reference-size", "32"],
    "peer_compare.py": ["--repeats", "1", "--counts", "500"],
    "first_call.py": ["--count", "500", "--pause", "0.05", "--repeats", "1"],
    "shader_ab.py": ["{repo}/shaders/wgsl", "{repo}/shaders/wgsl", "--rounds", "2", "--count", "500"],
    "lavapipe_profile.py": ["--seconds", "2", "--count", "500", "--frequency", "499"],
    "dispatch_split.py": ["--workgroups", "64", "--heavy", "100", "--repeats", "1", "--count", "500",
                          "--size", "64"],
    "sort.py": ["--depth-keys", "3000", "--tile-keys", "5000", "--rounds", "2", "--repeat", "1"],
    "body_posing.py": ["--per-face", "1", "--frames", "2"],
    "synth.py": ["--size", "48", "--train-frames", "4", "--texture-size", "256"],
    "viewer_fps.py": ["--size", "96x64", "--surfels", "2000", "--frames", "3", "--fine-per-face", "1"],
    "avatar_decode.py": ["--size", "64"],
    "fit_presets.py": ["--seq", "{tmp}/seq", "--out", "{tmp}/out"],
    "ablations.py": ["--seq", "{tmp}/seq", "--out", "{tmp}/out", "--steps", "2", "2"],
    "shared_decoders.py": ["--seq", "{tmp}/seq", "--out", "{tmp}/out", "--train-seeds", "1", "2"],
    "interop.py": ["--size", "32", "--quick"],
    "edit.py": ["--repeats", "1"],
    "pose_refine.py": ["--size", "32", "--fit-steps", "2", "--align-fit-steps", "2", "--align-steps", "1",
                       "--refine-steps", "1"],
    "fit_step.py": ["--work", "{tmp}/work", "--baseline", "{repo}"],
    "viewer_edit.py": ["--size", "96x64", "--fine-per-face", "1", "--feature-dim", "8", "--faces", "100",
                       "--repeats", "1", "--stroke-frames", "3"],
    "edit_pictures.py": ["--out", "{tmp}", "--size", "64"],
    "unseen_sides.py": ["--size", "48", "--frames", "12", "--steps", "1", "1", "--work", "{tmp}/work", "--figure",
                        "{tmp}/back.png"],
    "batch_scaling.py": ["--people", "1", "--size", "32", "--steps", "1", "1", "--out", "{tmp}/out"],
    "video_fit.py": "needs the video extra (MediaPipe), run by hand: python benchmarks/video_fit.py",
    "video_masks.py": ["--work", "{tmp}/work"],
    "video_hdr.py": ["--work", "{tmp}/work", "--figure", "{tmp}/hdr.png"],
    "video_to_avatar.py": "needs the video extra and minutes of fitting: python benchmarks/video_to_avatar.py",
    "unseen_real.py": "needs the iPER clip and a quick fit: python benchmarks/unseen_real.py",
    "closeups.py": "needs two avatars of one sequence; test_closeups_picture_of_two_avatars runs it small",
    "web_export.py": "needs Debian's chromium and minutes of software WebGL; tests/test_web_export.py covers "
                     "the page in a browser: python benchmarks/web_export.py",
    "report.py": "runs the other scripts; test_report_names_machine_commit_and_command runs it small",
}
# Scripts that read the iPER clip, which the repository does not ship (research use only; docs/data.md):
# skipped, with why, where it is absent. The lookup is benchmarks/common.py's iper_clip().
IPER_CLIP = Path(os.environ.get("GMA_IPER_CLIP") or REPO / "data" / "iper_turn_512.gif")
NEEDS = {"video_hdr.py": IPER_CLIP, "video_masks.py": IPER_CLIP}


def test_every_script_has_a_smoke_row():
    scripts = {p.name for p in BENCH.glob("*.py")} - HELPERS
    assert scripts == set(SMOKE), f"add rows for {sorted(scripts - set(SMOKE))}, drop {sorted(set(SMOKE) - scripts)}"


SMOKE_JOBS = min(2, os.cpu_count() or 1)
# Scripts that get a process of their own: they time a process's first calls, or start and stop a runtime
# (Ray) or a display (Xvfb) of their own, which a process shared with other scripts could disturb.
OWN_PROCESS = {"first_call.py", "batch_scaling.py", "viewer_fps.py", "viewer_edit.py", "lavapipe_profile.py"}


def _skip_reason(script: str) -> str | None:
    args = SMOKE[script]
    if isinstance(args, str):
        return args
    if script in NEEDS and not NEEDS[script].is_file():
        return f"needs {NEEDS[script]}, which this checkout lacks"
    return None


def _run_group(scripts: list[str], root: Path) -> dict[str, dict]:
    """Run ``scripts`` one after another in one process (tests/smoke_runner.py), each in a fresh folder
    under ``root``: {script: {"cmd", "returncode", "stdout", "stderr"}}. A script whose result is missing
    (the process died in it, or before it) gets the process's own output."""
    spec, cmds = [], {}
    for script in scripts:
        folder = root / Path(script).stem
        folder.mkdir()
        args = [a.format(tmp=folder, repo=REPO) for a in SMOKE[script]]
        spec.append([str(BENCH / script), str(folder), args])
        cmds[script] = " ".join([sys.executable, str(BENCH / script), *args])
    results = root / "results"
    results.mkdir()
    (root / "spec.json").write_text(json.dumps(spec))
    env = dict(os.environ, GMA_BENCH_SMOKE="1", PYTHONPATH=str(REPO))
    proc = subprocess.run([sys.executable, str(REPO / "tests" / "smoke_runner.py"), str(results),
                           str(root / "spec.json")], cwd=root, env=env, capture_output=True, text=True,
                          timeout=600 * len(scripts))
    out = {}
    for script in scripts:
        path = results / f"{script}.json"
        result = json.loads(path.read_text()) if path.is_file() else {
            "returncode": proc.returncode or 1, "stdout": proc.stdout, "stderr": f"no result: {proc.stderr}"}
        out[script] = {"cmd": cmds[script], **result}
    return out


def _groups(scripts: list[str]) -> list[list[str]]:
    """The shared-process scripts in SMOKE_JOBS groups (alternating in name order), then one group per
    script of OWN_PROCESS."""
    shared = [s for s in scripts if s not in OWN_PROCESS]
    return [g for g in (shared[i::SMOKE_JOBS] for i in range(SMOKE_JOBS)) if g] + \
        [[s] for s in scripts if s in OWN_PROCESS]


@pytest.fixture(scope="module")
def smoke_runs(request, tmp_path_factory, anny_body) -> dict[str, Future]:
    """The smoke runs of the runnable scripts whose tests were selected (``-k``): most share a process in
    SMOKE_JOBS groups run at once, the rest run alone after them. (``anny_body``: the body model's cache
    exists before two scripts could both set out to build it.)"""
    selected = {item.callspec.params["script"] for item in request.session.items
                if getattr(item, "originalname", None) == "test_benchmark_runs"}
    runnable = sorted(s for s in selected if _skip_reason(s) is None)
    with ThreadPoolExecutor(SMOKE_JOBS, thread_name_prefix="smoke") as pool:
        futures = {}
        for k, group in enumerate(_groups(runnable)):
            done = pool.submit(_run_group, group, tmp_path_factory.mktemp(f"smoke{k}"))
            futures.update({script: done for script in group})
        yield futures


@pytest.mark.slow
@pytest.mark.gpu
@pytest.mark.parametrize("script", sorted(SMOKE))
def test_benchmark_runs(script, smoke_runs):
    reason = _skip_reason(script)
    if reason:
        pytest.skip(reason)
    out = smoke_runs[script].result()[script]
    assert out["returncode"] == 0, f"{out['cmd']}\n{out['stdout'][-2000:]}\n{out['stderr'][-3000:]}"


@pytest.mark.parametrize("args", [["interop.py", "--size", "0"], ["interop.py", "--size", "99999"],
                                  ["shader_ab.py", "shaders/wgsl", "shaders/wgsl", "--size", "8"]])
def test_out_of_range_sizes_get_one_line_and_exit_2(args):
    """A size the renderer cannot take is refused with its range before any GPU or avatar work (it used to
    fail inside the renderer with a traceback)."""
    out = subprocess.run([sys.executable, str(BENCH / args[0]), *args[1:]], cwd=REPO, capture_output=True,
                         text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert out.returncode == 2, out.stderr
    assert "Traceback" not in out.stderr and "must lie in" in out.stderr.strip().splitlines()[-1]


def test_machine_line_names_the_processor_and_torchs_vector_width():
    """Benchmarks print the processor, and torch's kernels' vector width once torch is imported (a peer in
    torch runs faster on AVX-512, where lavapipe does not use it): ratios from two machine kinds differ."""
    code = ("import sys; sys.path.insert(0, sys.argv[1]); from common import machine; print(machine()); "
            "import torch; print(machine()); print(torch.backends.cpu.get_cpu_capability())")
    out = subprocess.run([sys.executable, "-c", code, str(BENCH)], capture_output=True, text=True, timeout=120)
    before, after, capability = out.stdout.strip().splitlines()
    assert f"{os.cpu_count()} cores" in before and "torch" not in before
    assert after.startswith(before.split(", load")[0]) and f", torch {capability}, load " in after


@pytest.mark.gpu
def test_shader_ab_toggles_a_rasterizer_switch():
    """``shader_ab.py --toggle SWITCH`` times this checkout's shaders with a RasterOptions switch off and
    on; directories beside it, or a name that is not a switch, get one line and exit 2."""
    def run(*args):
        return subprocess.run([sys.executable, str(BENCH / "shader_ab.py"), *args, "--rounds", "2", "--count",
                               "500"], cwd=REPO, capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, PYTHONPATH=str(REPO)))
    out = run("--toggle", "work_queues")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "rasterize_bwd" in out.stdout and "B/A" in out.stdout
    for args, message in ((("--toggle", "no_such_switch"), "not a switch of RasterOptions"),
                          (("--toggle", "queue_workgroups"), "not a switch of RasterOptions"),
                          (("--toggle", "work_queues", "shaders/wgsl", "shaders/wgsl"), "give two shader"),
                          (("shaders/wgsl",), "give two shader")):
        bad = run(*args)
        assert bad.returncode == 2 and "Traceback" not in bad.stderr, bad.stderr
        assert message in bad.stderr.strip().splitlines()[-1]


@pytest.mark.gpu
def test_shader_ab_times_public_steps():
    """``shader_ab.py A B --public`` times whole forward+backward steps of the public call with each
    directory's pipelines in one process and prints both gradient sums (the same shaders: equal); with
    ``--toggle``, or fewer than 2 rounds (the first only warms up), it gets one line and exit 2."""
    def run(*args):
        return subprocess.run([sys.executable, str(BENCH / "shader_ab.py"), *args, "--public", "--count", "500"],
                              cwd=REPO, capture_output=True, text=True, timeout=600,
                              env=dict(os.environ, PYTHONPATH=str(REPO)))
    out = run("shaders/wgsl", "shaders/wgsl", "--rounds", "2")
    assert out.returncode == 0, out.stderr[-3000:]
    assert "public forward+backward" in out.stdout and "(2 steps each)" in out.stdout
    sums = out.stdout.strip().splitlines()[-1]
    a, b = (part.split(",")[0].strip() for part in sums.split(": A ")[1].split("B "))
    assert a == b and float(a) > 0
    for args, message in ((("--toggle", "work_queues"), "--public compares two shader directories"),
                          (("shaders/wgsl", "shaders/wgsl", "--rounds", "1"), "--public needs at least 2")):
        bad = run(*args)
        assert bad.returncode == 2 and "Traceback" not in bad.stderr, bad.stderr
        assert message in bad.stderr.strip().splitlines()[-1]


def test_first_call_refuses_a_pause_that_is_not_positive():
    """``first_call.py --pause 0`` (or a negative or non-numeric pause) gets one line naming the option and
    exit 2, before it renders anything."""
    for value in ("0", "-1", "soon"):
        bad = subprocess.run([sys.executable, str(BENCH / "first_call.py"), "--pause", value, "--count", "500"],
                             cwd=REPO, capture_output=True, text=True, timeout=300,
                             env=dict(os.environ, PYTHONPATH=str(REPO)))
        assert bad.returncode == 2 and "Traceback" not in bad.stderr, bad.stderr
        assert "--pause" in bad.stderr.strip().splitlines()[-1] and bad.stdout == ""


@pytest.mark.gpu
def test_report_names_machine_commit_and_command(tmp_path):
    """``report.py --quick`` writes its results file where ``--out`` says: machine, adapter, commit, date and
    the command that made it, a row of figures from the script it ran, and no row for the ones left out."""
    out = tmp_path / "RESULTS.md"
    args = ["--quick", "--only", "render", "--out", str(out)]
    run = subprocess.run([sys.executable, str(BENCH / "report.py"), *args], cwd=REPO, capture_output=True,
                         text=True, timeout=600, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 0, run.stderr[-3000:]
    text = out.read_text()
    for line in ("- machine: ", "- adapter: ", "- commit: ", "- date: ", f"- command: `python benchmarks/report.py "
                                                                         f"{' '.join(args)}`"):
        assert line in text, line
    assert f"{os.cpu_count()} cores" in text and "Quick mode" in text
    assert "| forward frame, standard 0.5k surfels at 512x512 | " in text and "peer ratio" not in text


@pytest.mark.parametrize("args, message", [(["--only", "nothing"], "--only nothing: no such benchmark"),
                                           (["--out", "/no/such/folder/R.md"], "its folder does not exist"),
                                           (["--update"], "name the rows to run again with --only"),
                                           (["--only", "web", "--update", "--out", "R.md"],
                                            "R.json: no earlier report to update")])
def test_report_refuses_bad_arguments_before_running_anything(tmp_path, args, message):
    run = subprocess.run([sys.executable, str(BENCH / "report.py"), "--quick", *args], cwd=tmp_path,
                         capture_output=True, text=True, timeout=120, env=dict(os.environ, PYTHONPATH=str(REPO)))
    assert run.returncode == 2 and "Traceback" not in run.stderr and run.stdout == "", run.stderr
    assert message in run.stderr.strip().splitlines()[-1]
def test_smoke_runner_keeps_each_scripts_outcome(tmp_path):
    """tests/smoke_runner.py runs scripts one after another in one process, each in its folder with its
    arguments as ``__main__``, and records each one's exit status, output and traceback on its own: a
    failing script does not stop the next, nor does its torch grad mode carry over."""
    scripts = {
        "ok.py": "import os, sys\nif __name__ == '__main__':\n    print('args', sys.argv[1:], os.getcwd())\n",
        "exits.py": "import sys\nsys.exit(3)\n",
        "raises.py": "import torch\ntorch.set_grad_enabled(False)\nraise ValueError('broken script')\n",
        "last.py": "import torch\nprint('still ran, gradients', torch.is_grad_enabled())\n",
    }
    spec = []
    for name, code in scripts.items():
        (tmp_path / name).write_text(code)
        (tmp_path / name[:-3]).mkdir()
        spec.append([str(tmp_path / name), str(tmp_path / name[:-3]), ["--x", "1"]])
    (tmp_path / "spec.json").write_text(json.dumps(spec))
    (tmp_path / "results").mkdir()
    out = subprocess.run([sys.executable, str(REPO / "tests" / "smoke_runner.py"), str(tmp_path / "results"),
                          str(tmp_path / "spec.json")], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    res = {name: json.loads((tmp_path / "results" / f"{name}.json").read_text()) for name in scripts}
    assert res["ok.py"]["returncode"] == 0 and f"args ['--x', '1'] {tmp_path / 'ok'}" in res["ok.py"]["stdout"]
    assert res["exits.py"]["returncode"] == 3
    assert res["raises.py"]["returncode"] == 1 and "ValueError: broken script" in res["raises.py"]["stderr"]
    # ... and what a script switched off process-wide in torch is on again for the next
    assert res["last.py"]["returncode"] == 0 and "still ran, gradients True" in res["last.py"]["stdout"]


@pytest.mark.gpu
def test_closeups_picture_of_two_avatars(tiny_sequence, anny_body, tmp_path, monkeypatch, capsys):
    """``closeups.py`` (skipped in the smoke runs: it needs two avatars of one sequence) on two unfitted
    avatars of the tiny sequence: one row per picked frame, test-time fitting of those frames only, and a
    frame outside the split refused in one line with exit code 2."""
    from gma.avatar import Avatar, AvatarConfig
    from gma.core.images import read_image

    monkeypatch.syspath_prepend(str(BENCH))
    import closeups

    seq = tiny_sequence(0)
    for name, seed in (("a", 0), ("b", 1)):
        Avatar.create(AvatarConfig(feature_dim=4, fine_per_face=1), anny_body, seed=seed).save(tmp_path / f"{name}.gma")
    frames = seq.split("test_pose")
    out = tmp_path / "closeups.png"
    args = [str(seq.root), str(tmp_path / "a.gma"), str(tmp_path / "b.gma"), "--split", "test_pose",
            "--resolution", "32", "--refine-steps", "1"]
    assert closeups.main([*args, "--out", str(out), "--frames", str(frames[-1])]) == 0
    picture = read_image(out)
    assert picture.shape[0] == closeups.ZOOM_PX and picture.shape[1] > 6 * closeups.ZOOM_PX  # one row
    with pytest.raises(SystemExit) as exit_:
        closeups.main([*args, "--out", str(tmp_path / "x.png"), "--frames", "999"])
    assert exit_.value.code == 2 and "999: not in split 'test_pose'" in capsys.readouterr().err.strip().splitlines()[-1]
    assert not (tmp_path / "x.png").exists()
