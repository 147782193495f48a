#!/usr/bin/env python3
"""Phone clips in HDR: the iPER clip (``common.iper_clip()``, SDR) turned into 10-bit HLG and
PQ the way BT.2408 places SDR white (203 cd/m²), then read back as ``gma import video`` reads it (tone
mapped, ``gma.video.read_video``) and as plain SDR decoding would; prints the mean absolute difference to
the SDR frames (levels, 0-255) and the decoding time per frame, and writes ``docs/video_hdr.png`` (a frame:
the SDR original | the HLG clip read as SDR | read by gma). Then the cost of a selection on a phone-sized
clip: the clip at 3840x2160, SDR and HLG, every 8th frame read the way ``gma import video --skip 8`` reads
it (ffmpeg drops the other frames before converting them) against decoding and converting every frame and
keeping every 8th (how it read before), in the same run.

    python benchmarks/video_hdr.py [--frames 53] [--figure docs/video_hdr.png] [--work /tmp/gma-hdr]
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from gma.data.importers.video import read_frames
from gma.video import read_video

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from common import iper_clip, iper_missing  # noqa: E402

CLIP = iper_clip()
TRANSFERS = {"HLG": "arib-std-b67", "PQ": "smpte2084"}


def encode_hdr(src: Path, dst: Path, transfer: str, frames: int, scale: str = "") -> None:
    """``src`` as a 10-bit HEVC clip with ``transfer``, SDR white at BT.2408's 203 cd/m² (``scale``: an
    ffmpeg scale filter to apply first, with its trailing comma)."""
    vf = (f"{scale}zscale=tin=bt709:min=bt709:pin=bt709:t={transfer}:m=bt2020nc:p=bt2020:npl=203,"
          "format=yuv420p10le")
    subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(src), "-frames:v",
                    str(frames), "-vf", vf, "-c:v", "libx265", "-x265-params", "log-level=error",
                    "-color_primaries", "bt2020", "-color_trc", transfer, "-colorspace", "bt2020nc", str(dst)],
                   check=True)


def read_as_sdr(path: Path) -> np.ndarray:
    """Frames decoded the plain way (what reading the clip without the tone mapping gives)."""
    gen = imageio_ffmpeg.read_frames(str(path))
    w, h = next(gen)["size"]
    return np.stack([np.frombuffer(f, np.uint8).reshape(h, w, 3) for f in gen])


def selection_speed(work: Path, frames: int, size: str, skip: int = 8) -> None:
    """Every ``skip``-th frame of the clip at ``size``, SDR and HLG: read as the import reads it, against
    every frame decoded and converted and every ``skip``-th kept (the same frames, asserted)."""
    print(f"every {skip}th of {frames} frames at {size.replace(':', 'x')}:")
    print(f"  {'clip':<5} {'all converted, s':>17} {'selected only, s':>17} {'speed-up':>9}")
    for name in ("SDR", "HLG"):
        clip = work / f"iper_{name.lower()}_{size.replace(':', 'x')}.mp4"
        if name == "SDR":
            subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-loglevel", "error", "-i", str(CLIP), "-frames:v",
                            str(frames), "-vf", f"scale={size},format=yuv420p", "-c:v", "libx264", "-crf", "18",
                            str(clip)], check=True)
        else:
            encode_hdr(CLIP, clip, TRANSFERS[name], frames, scale=f"scale={size},")
        t0 = time.perf_counter()
        kept = [f.copy() for k, f in enumerate(read_frames(clip, False)) if k % skip == 0]
        t1 = time.perf_counter()
        selected, _ = read_video(clip, skip=skip)
        t2 = time.perf_counter()
        assert np.array_equal(np.stack(kept), selected)
        print(f"  {name:<5} {t1 - t0:17.2f} {t2 - t1:17.2f} {(t1 - t0) / (t2 - t1):8.1f}x")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--frames", type=int, default=53)
    ap.add_argument("--figure", default=str(REPO / "docs" / "video_hdr.png"))
    ap.add_argument("--work", default="/tmp/gma-hdr")
    args = ap.parse_args()
    smoke = os.environ.get("GMA_BENCH_SMOKE") == "1"
    if not CLIP.is_file():
        print(iper_missing(CLIP), file=sys.stderr)
        return 2
    frames = 3 if smoke else args.frames
    work = Path(args.work)
    work.mkdir(parents=True, exist_ok=True)
    sdr = np.asarray(iio.imread(CLIP, index=None))[:frames, ..., :3].astype(np.float32)
    print(f"{CLIP.name}: {frames} frames at {sdr.shape[2]}x{sdr.shape[1]}, mean level {sdr.mean():.1f}")
    print(f"  {'clip':<5} {'read as SDR':>12} {'read by gma':>12} {'ms/frame (SDR read)':>20} {'ms/frame (gma)':>15}")
    shown = {}
    for name, transfer in TRANSFERS.items():
        clip = work / f"iper_{name.lower()}.mp4"
        encode_hdr(CLIP, clip, transfer, frames)
        t0 = time.perf_counter()
        plain = read_as_sdr(clip)
        t1 = time.perf_counter()
        info: dict = {}
        mapped, _ = read_video(clip, info=info)
        t2 = time.perf_counter()
        assert info.get("hdr") == name, info
        print(f"  {name:<5} {np.abs(plain - sdr).mean():12.1f} {np.abs(mapped - sdr).mean():12.1f} "
              f"{1e3 * (t1 - t0) / frames:20.1f} {1e3 * (t2 - t1) / frames:15.1f}")
        shown[name] = (plain, mapped)
    print("  (mean absolute difference to the SDR frames, levels 0-255; the HDR clips are lossy 10-bit encodes)")
    if not smoke:
        plain, mapped = shown["HLG"]
        k = min(5, frames - 1)
        gap = np.full((sdr.shape[1], 8, 3), 255, np.uint8)
        iio.imwrite(args.figure, np.concatenate([sdr[k].astype(np.uint8), gap, plain[k], gap, mapped[k]], 1))
        print(f"  wrote {args.figure} (frame {k}: SDR original | HLG clip read as SDR | HLG clip read by gma)")
    selection_speed(work, 9 if smoke else args.frames, "960:540" if smoke else "3840:2160")
    return 0


if __name__ == "__main__":
    sys.exit(main())
