#!/usr/bin/env python3
"""The two steps a fit is made of, timed: a pose-fitting step (one frame's pose corrections against its
image with the avatar frozen: the fit's alignment pass, 30 per training frame, and test-time fitting in
``gma eval --refine-poses``) and a training step (decode with gradients, pose, render, loss, backward,
Adam). Each checkout runs in its own worker process; ``--baseline DIR`` times another checkout (e.g.
``git worktree add /tmp/base <commit>``) the same way, turns alternating, so a speed-up over earlier code
is a ratio from one run. Medians of ms per step.

By default a synthetic sequence (256 px, 6 training frames) and a fresh avatar of the quick preset,
written to ``--work``; ``--avatar A.gma --sequence DIR`` times a fitted avatar on its own sequence.

    python benchmarks/fit_step.py [--baseline DIR] [--repeats 5] [--steps 8] [--avatar A.gma --sequence DIR]
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import CheckoutWorker, machine, parse_env, wrong_checkout  # noqa: E402

SMOKE = os.environ.get("GMA_BENCH_SMOKE") == "1"


def default_inputs(work: Path) -> tuple[Path, Path]:
    """(avatar, sequence): a synthetic sequence and a fresh quick-preset avatar on its body, made once."""
    from gma.avatar import Avatar
    from gma.body import load_body
    from gma.data import read_sequence
    from gma.synth.generate import SynthConfig, synthesize
    from gma.train.config import preset

    seq_dir, avatar = work / "seq", work / "avatar.gma"
    if not (seq_dir / "cameras.json").is_file():
        size = 48 if SMOKE else 256
        synthesize(seq_dir, SynthConfig(width=size, height=size, train_frames=2 if SMOKE else 6, test_pose_frames=1,
                                        test_view_frames=1, supersample=1, texture_size=128 if SMOKE else 512),
                   progress=False)
    if not avatar.is_file():
        cfg = preset("quick").avatar
        if SMOKE:
            cfg = preset("quick", avatar={"feature_dim": 8, "fine_per_face": 1}).avatar
        seq = read_sequence(seq_dir)
        body = load_body(seq.body.model)
        Avatar.create(cfg, body, shape=seq.body.frame(0)["phenotype"]).save(avatar)
    return avatar, seq_dir


class Worker(CheckoutWorker):
    """One checkout's GMA in a worker process (this script with ``--worker``): each request times a burst
    of steps there."""

    def __init__(self, root: Path, avatar: Path, seq: Path, env: dict[str, str] | None = None):
        super().__init__(root, __file__, str(avatar), str(seq), env=env)

    def time(self, kind: str, steps: int) -> float:
        return float(self.ask(f"{kind} {steps}"))


def worker(avatar_path: str, seq_path: str) -> int:
    """Load the avatar and the training frames at the quick preset's resolution, then answer "pose K" /
    "train K" with the mean ms of K steps. Uses only calls that earlier checkouts have too."""
    import torch

    from gma.avatar import Avatar
    from gma.body import load_body
    from gma.data import read_sequence
    from gma.gpu import get_context
    from gma.train.data import load_frames
    from gma.train.losses import picture_loss
    from gma.train.pose_refine import BONE_SETS, PoseCorrections, PoseRefineConfig, fit_corrections
    from gma.train.render_step import render_frame

    error = wrong_checkout()
    if error:
        print(error, flush=True)
        return 2
    avatar, seq = Avatar.load(Path(avatar_path)), read_sequence(Path(seq_path))
    body, ctx = load_body(avatar.body_name), get_context()
    frames = load_frames(seq, body, "train", 48 if SMOKE else 192, identity=avatar.shape)
    with torch.no_grad():
        frozen = avatar.model.decode(avatar.render_layer).detach()
    opt = torch.optim.Adam(avatar.model.parameters(), lr=1e-6)
    cfg = PoseRefineConfig()
    turn = 0

    def pose_steps(k: int) -> None:
        corr = PoseCorrections(body, frames.poses, frames.indices, BONE_SETS[cfg.bones])
        fit_corrections(corr, frozen, body, _Prefix(frames, 1), k, cfg, 0.5, ctx)  # frame 0, k steps

    def train_steps(k: int) -> None:
        for i in range(k):
            t = (turn * k + i) % len(frames)
            decoded = avatar.model.decode(avatar.render_layer)
            out, _ = render_frame(decoded, body, frames, t, 0.5, ctx, cull=True)
            l1, dssim = picture_loss(out.color, frames.target(t, 0.5))
            (0.8 * l1 + 0.2 * dssim).backward()
            opt.step()
            opt.zero_grad(set_to_none=True)

    pose_steps(2)  # compile the pipelines
    train_steps(2)
    print(f"ready {ctx.name}", flush=True)
    for line in sys.stdin:
        kind, k = line.split()
        time.sleep(0.3)  # let the other side's threads settle
        t0 = time.perf_counter()
        (pose_steps if kind == "pose" else train_steps)(int(k))
        print(f"{(time.perf_counter() - t0) / int(k) * 1e3:.3f}", flush=True)
        turn += 1
    return 0


class _Prefix:
    """The first ``n`` frames of a frame set (``fit_corrections`` fits every frame of what it is given)."""

    def __init__(self, frames, n: int):
        self._frames, self._n = frames, n

    def __len__(self) -> int:
        return self._n

    def __getattr__(self, name):
        return getattr(self._frames, name)


def main() -> int:
    if len(sys.argv) == 4 and sys.argv[1] == "--worker":
        return worker(sys.argv[2], sys.argv[3])
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--baseline", type=Path, help="another GMA checkout to time beside this one")
    ap.add_argument("--baseline-env", action="append", metavar="KEY=VALUE",
                    help="KEY=VALUE for the baseline's worker only (repeatable); with --baseline . the "
                         "same code with, e.g., other shaders: GMA_SHADER_DIR=/tmp/b")
    ap.add_argument("--repeats", type=int, default=1 if SMOKE else 5, help="turns per side and step kind")
    ap.add_argument("--steps", type=int, default=1 if SMOKE else 8, help="steps per turn")
    ap.add_argument("--avatar", type=Path, help="a fitted avatar (with --sequence)")
    ap.add_argument("--sequence", type=Path, help="the avatar's sequence")
    ap.add_argument("--work", type=Path, help="where the default sequence and avatar are kept (default: a temp dir)")
    args = ap.parse_args()
    if (args.avatar is None) != (args.sequence is None):
        ap.error("--avatar and --sequence go together")
    if args.avatar is not None and not args.avatar.is_file():
        ap.error(f"{args.avatar}: no such avatar file")
    if args.sequence is not None:
        from gma.data.sequence import REQUIRED_ENTRIES

        missing = [n for n in REQUIRED_ENTRIES if not (args.sequence / n).exists()]
        if missing:
            ap.error(f"{args.sequence}: not a sequence folder (no {', '.join(missing)})")
    if args.baseline is not None:
        CheckoutWorker.checkout(args.baseline)  # before the inputs are made
    with tempfile.TemporaryDirectory() as tmp:
        if args.avatar is None:
            work = args.work or Path(tmp)
            work.mkdir(parents=True, exist_ok=True)
            avatar, seq = default_inputs(work)
        else:
            avatar, seq = args.avatar.resolve(), args.sequence.resolve()
        sides = {"this checkout": Worker(REPO, avatar, seq)}
        if args.baseline is not None:
            sides["baseline"] = Worker(args.baseline, avatar, seq, parse_env(args.baseline_env))
        times = {(name, kind): [] for name in sides for kind in ("pose", "train")}
        for r in range(args.repeats):
            order = list(sides.items()) if r % 2 == 0 else list(reversed(sides.items()))
            for kind in ("pose", "train"):
                for name, w in order:
                    times[name, kind].append(w.time(kind, args.steps))
        for w in sides.values():
            w.close()
    for name, w in sides.items():
        print(f"  {name}: {w.banner or 'adapter not reported'}")
    print(f"fit steps ({avatar.name}, {args.repeats} turns of {args.steps} steps per side; {machine()})")
    for (name, kind), v in times.items():
        label = "pose-fitting step" if kind == "pose" else "training step"
        print(f"  {name:<14} {label:<18} median {statistics.median(v):7.1f} ms   turns {[round(x) for x in v]}")
    if args.baseline is not None:
        for kind in ("pose", "train"):
            ratio = statistics.median(times["baseline", kind]) / statistics.median(times["this checkout", kind])
            print(f"  {kind}: baseline / this checkout = {ratio:.2f}x")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
