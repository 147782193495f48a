"""Avatar costs outside training: full decode (torch MLPs, once per load or edit), a local re-decode of
an edited region, file size and load time, and per-frame GPU posing + rendering.

    python benchmarks/avatar_decode.py [AVATAR.gma] [--size 512]
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path


def _ms(f, n=5) -> float:
    f()
    t = time.perf_counter()
    for _ in range(n):
        f()
    return 1000 * (time.perf_counter() - t) / n


def main() -> int:
    import numpy as np
    import torch

    from gma.avatar import Avatar, AvatarConfig
    from gma.avatar.gpu import AvatarRenderer
    from gma.avatar.video import orbit_cameras
    from gma.body import load_body
    from gma.data.cameras import look_at
    from gma.gpu import get_context

    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("avatar", nargs="?", help="a .gma file (default: a fresh full-preset-sized avatar)")
    p.add_argument("--size", type=int, default=512)
    p.add_argument("--threads", type=int, default=1)
    args = p.parse_args()
    torch.set_num_threads(args.threads)
    body = load_body("anny")
    if args.avatar:
        t = time.perf_counter()
        av = Avatar.load(args.avatar, body)
        load_ms = 1000 * (time.perf_counter() - t)
        path = Path(args.avatar)
    else:
        av = Avatar.create(AvatarConfig(feature_dim=32, fine_per_face=4), body)
        path = av.save(Path("out/bench/fresh.gma"))
        t = time.perf_counter()
        Avatar.load(path, body)
        load_ms = 1000 * (time.perf_counter() - t)
    print(f"avatar {path}: {path.stat().st_size / 2**20:.2f} MiB, load {load_ms:.0f} ms, "
          f"{len(av.decode().binding)} surfels (k={av.config.feature_dim}, N_k={av.config.fine_per_face})")
    print(f"full decode: {_ms(av.decode):.1f} ms")
    dec = av.decode()
    faces = torch.nonzero(body.region_mask("head")).flatten() if "head" in body.regions else torch.arange(2000)
    print(f"re-decode of an edited region ({len(faces)} faces): "
          f"{_ms(lambda: av.model.redecode_faces(dec, faces)):.1f} ms")
    ctx = get_context()
    r = AvatarRenderer(ctx, av, body)
    s = args.size
    f = s * 1.3
    K = np.array([[f, 0, s / 2], [0, f, s / 2], [0, 0, 1]], np.float32)
    cam = orbit_cameras(look_at([0, -2.6, 0.25], [0, 0, -0.05], [0, 0, 1]), K, s, s, 1)[0]
    from gma.body import motion

    m = motion("walk", frames=30, body=body, shape=av.shape)
    i = [0]

    def frame():
        i[0] += 1
        r.render(m.params(i[0]), cam, (1, 1, 1))

    print(f"GPU pose + render + read-back at {s}x{s}: {_ms(frame, 10):.1f} ms/frame on {ctx.name}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
