"""A user's own video: ``gma import video clip.mp4 OUT --body params.npz --camera cam.json``.

Frames are read with imageio (ffmpeg). The person's mask comes from one of: the video's alpha channel
(``alpha=True``; needs a codec that keeps alpha, e.g. ProRes 4444, PNG-in-MOV, VP9 WebM), a mask video
(``mask_video``, grey or RGB, person bright), or a folder of mask images (``mask_dir``, sorted by name,
one per video frame). Body parameters (``body.npz`` of the sequence format) and cameras
(``cameras.json``) are given by the user, either for every video frame or for exactly the frames
selected by ``start``/``end``/``skip``. Without body parameters and cameras, ``gma.video.estimate_sequence``
estimates masks, camera and body from the video itself (``gma import video clip.mp4 OUT``).
"""

from __future__ import annotations

import logging
import os
import re
import subprocess
from collections.abc import Iterator
from contextlib import ExitStack, closing
from pathlib import Path

import imageio.v3 as iio
import imageio_ffmpeg
import numpy as np

from gma.body.params import load_body, require_body_model
from gma.core.errors import InputError
from gma.data.cameras import load_cameras
from gma.data.importers._common import frame_range, mask_from_array, write_imported
from gma.data.sequence import IMAGE_SUFFIXES, Sequence

__all__ = ["count_frames", "import_video"]


def count_frames(path: str | os.PathLike) -> int:
    """Number of frames in a video file. It decodes the clip once (container frame counts are unreliable),
    but converts nothing: no RGB frames, no tone mapping (an HDR 4K clip counts several times faster than
    it reads)."""
    proc = _ffmpeg_on(path, "-map", "0:v:0", "-f", "null", "-")
    counts = re.findall(r"frame=\s*(\d+)", proc.stderr)
    if proc.returncode != 0 or not counts:
        lines = [ln.strip() for ln in proc.stderr.splitlines() if ln.strip()]
        raise ValueError(f"{path}: cannot open as a video ({lines[-1] if lines else 'ffmpeg failed'})")
    return int(counts[-1])


def _ffmpeg_on(path, *args: str) -> subprocess.CompletedProcess:
    """ffmpeg run on input ``path`` with output ``args`` (none: it only describes the file); its log is in
    ``stderr``."""
    return subprocess.run([imageio_ffmpeg.get_ffmpeg_exe(), "-hide_banner", "-nostdin", "-i", str(path), *args],
                          capture_output=True, text=True, errors="replace")


class _RotatedFrameNotice(logging.Filter):
    """Drops imageio-ffmpeg's warning that the frames read differ in size from the stored ones. Phones
    store a portrait video as landscape frames plus a display rotation; ffmpeg applies the rotation, so
    the frames come out upright (the size ffmpeg reports for them is the one used) and the warning would
    only make a user think something went wrong."""

    def filter(self, record: logging.LogRecord) -> bool:
        return "is different from the source frame size" not in record.getMessage()


logging.getLogger("imageio_ffmpeg").addFilter(_RotatedFrameNotice())


# HDR transfer functions as ffmpeg names them, and what to call them: phones record HDR by default
# (iPhones HLG, many Android phones PQ / HDR10), and decoded as if SDR such a clip comes out dim and grey
# (the iPER clip as HLG: 43.5 levels off on average, PQ 70.2; benchmarks/video_hdr.py), which the avatar
# would learn.
HDR_TRANSFERS = {"arib-std-b67": "HLG", "smpte2084": "PQ"}
# HDR to SDR (BT.709) the simple way: BT.2408's HDR reference white (203 cd/m²) becomes SDR white and
# brighter highlights clip, so everything up to white keeps its level (an SDR clip turned into HLG or PQ
# this way reads back within 3-4 levels of the original; curves such as hable or mobius darken every
# pixel to make room for highlights a person's clothes rarely have).
TO_SDR = ("zscale=t=linear:npl=203,format=gbrpf32le,zscale=p=bt709,tonemap=tonemap=clip:desat=0,"
          "zscale=t=bt709:m=bt709:r=tv,format=yuv420p")


def probe_transfer(path) -> str | None:
    """``"HLG"`` or ``"PQ"`` when ffmpeg's description of the file (``ffmpeg -i``, which decodes nothing)
    names an HDR transfer for its first video stream, else None."""
    video = next((ln for ln in _ffmpeg_on(path).stderr.splitlines() if "Video:" in ln), "")
    return next((name for key, name in HDR_TRANSFERS.items() if key in video), None)


def hdr_transfer(meta: dict) -> str | None:
    """``"HLG"`` or ``"PQ"`` when imageio-ffmpeg's ``meta`` describes an HDR video stream, else None."""
    pix_fmt = str(meta.get("pix_fmt", ""))
    return next((name for key, name in HDR_TRANSFERS.items() if key in pix_fmt), None)


def read_frames(path, alpha: bool, info: dict | None = None,
                select: tuple[int, int | None, int] | None = None) -> Iterator[np.ndarray]:
    """Decoded frames uint8 [H, W, 3] (or [H, W, 4] with ``alpha``), through imageio's ffmpeg, upright (a
    video's display rotation, as in a phone's portrait clip, is applied) and in SDR: an HDR clip (HLG or
    PQ) is tone-mapped (see ``TO_SDR``), and ``info["hdr"]`` says which it was; ``info["frames_estimate"]``:
    the frame count the header implies, when it gives a frame rate and a duration.

    ``select = (start, end, skip)``: only frames ``start, start + skip, ... < end`` come out (``end`` None:
    to the clip's end). ffmpeg still decodes every frame (a compressed clip cannot skip), but drops the
    others before converting them, so the RGB conversion, the tone mapping and the pipe are paid for the
    selected frames alone, which matters most for HLG; in SDR decoding is most of the time
    (``benchmarks/video_hdr.py``)."""
    channels = 4 if alpha else 3
    vf = [] if select is None else [select_filter(*select)]

    def start(filters):
        if not filters:
            return open_frames(path, alpha, None)
        params = ["-vf", ",".join(filters)]
        if select is None:
            return open_frames(path, alpha, params)
        try:  # kept frames keep their timestamps: passthrough, or ffmpeg fills the gaps with copies
            return open_frames(path, alpha, params + ["-fps_mode", "passthrough"])
        except ValueError as exc:
            if "fps_mode" not in str(exc):
                raise
            return open_frames(path, alpha, params + ["-vsync", "passthrough"])  # ffmpeg before 5.1

    def start_sdr(hdr):
        if hdr is None:
            return start(vf)
        try:
            return start(vf + [TO_SDR])
        except ValueError as exc:
            raise InputError(f"{path}: an HDR ({hdr}) video, and this ffmpeg cannot tone-map it to SDR (it needs the "
                             "zscale and tonemap filters, which imageio-ffmpeg's own ffmpeg has: pip install -U "
                             "imageio-ffmpeg)") from exc

    # The transfer from ffmpeg's description of the file first (no decoding), so that the clip is opened
    # once: opening a 4K clip to look and then again to tone-map would cost a second open. The stream ffmpeg
    # decodes has the last word.
    hdr = None if alpha else probe_transfer(path)  # a clip with alpha is read as it is
    gen, meta = start_sdr(hdr)
    if not alpha and hdr_transfer(meta) != hdr:
        gen.close()
        hdr = hdr_transfer(meta)
        gen, meta = start_sdr(hdr)
    if info is not None and hdr is not None:
        info["hdr"] = hdr
    if info is not None and meta.get("fps") and meta.get("duration"):
        info["frames_estimate"] = round(meta["fps"] * meta["duration"])  # from the header: may be off a little
    w, h = meta["size"]
    try:
        for raw in gen:
            yield np.frombuffer(raw, np.uint8).reshape(h, w, channels)
    finally:
        gen.close()


def open_frames(path, alpha: bool, output_params: list[str] | None):
    """imageio-ffmpeg's frame generator for ``path`` and the clip's metadata (its first item)."""
    try:
        gen = imageio_ffmpeg.read_frames(str(path), pix_fmt="rgba" if alpha else "rgb24", bpp=4 if alpha else 3,
                                         output_params=output_params)
        return gen, next(gen)
    except (OSError, RuntimeError, StopIteration) as exc:
        raise ValueError(f"{path}: cannot open as a video ({exc})") from exc


def select_filter(start: int, end: int | None, skip: int) -> str:
    """ffmpeg's filter that keeps frames ``start, start + skip, ... < end`` (``n``: the decoded frame's
    index; the commas of the expression escaped from the filter graph)."""
    terms = [f"gte(n\\,{start})", f"not(mod(n-{start}\\,{skip}))"]
    if end is not None:
        terms.append(f"lt(n\\,{end})")
    return "select=" + "*".join(terms)


def import_video(
    src: str | os.PathLike,
    out: str | os.PathLike,
    *,
    body: str | os.PathLike,
    camera: str | os.PathLike,
    alpha: bool = False,
    mask_video: str | os.PathLike | None = None,
    mask_dir: str | os.PathLike | None = None,
    start: int = 0,
    end: int | None = None,
    skip: int = 1,
    model_dir: str | os.PathLike | None = None,
    downscale: int = 1,
    overwrite: bool = False,
) -> Sequence:
    """Import video ``src`` with user-supplied body parameters and cameras into a sequence ``out``."""
    src = Path(src)
    if not src.is_file():
        raise FileNotFoundError(f"{src}: video not found")
    if sum(x is not None and x is not False for x in (alpha or None, mask_video, mask_dir)) != 1:
        raise ValueError("give exactly one mask source: --alpha, --mask-video or --mask-dir")
    n = count_frames(src)
    if n == 0:
        raise ValueError(f"{src}: the video has no frames")
    idx = frame_range(n, start, end, skip)
    mask_files = _check_masks(src, n, mask_video, mask_dir)
    params = _body_of_frames(body, model_dir, src, n, idx)
    cams = _cameras_of_frames(camera, n, idx)
    frames = _frames(src, set(idx), alpha, mask_video, mask_files)
    return write_imported(out, frames, len(idx), cams, params, None, downscale, overwrite, "video")


def _check_masks(src: Path, n: int, mask_video, mask_dir) -> list[Path] | None:
    """The mask folder's images (one per video frame), or None; a mask video must have ``n`` frames too."""
    mask_files = None
    if mask_dir is not None:
        mask_files = sorted(p for p in Path(mask_dir).glob("*") if p.suffix.lower() in IMAGE_SUFFIXES)
        if len(mask_files) != n:
            raise ValueError(f"{mask_dir}: {len(mask_files)} mask images for {n} video frames")
    if mask_video is not None:
        if not Path(mask_video).is_file():
            raise FileNotFoundError(f"{mask_video}: mask video not found")
        m = count_frames(mask_video)
        if m != n:
            raise ValueError(f"{mask_video}: {m} frames, but {src} has {n}")
    return mask_files


def _body_of_frames(body, model_dir, src: Path, n: int, idx: list[int]):
    """The body parameters of the selected frames ``idx`` (given for all ``n`` frames or for those)."""
    params = load_body(body)
    require_body_model(params, str(body), model_dir)
    if params.num_frames == n and len(idx) != n:
        params = params.subset(idx)
    elif params.num_frames != len(idx):
        raise ValueError(
            f"{body}: {params.num_frames} frames of body parameters, but {src} has {n} frames "
            f"({len(idx)} selected)"
        )
    return params


def _cameras_of_frames(camera, n: int, idx: list[int]):
    """The cameras of the selected frames ``idx``: one static camera, or per-frame ones given for all
    ``n`` frames or for those."""
    cams = load_cameras(camera)
    if not cams.static:
        if cams.K.shape[0] == n or cams.w2c.shape[0] == n:
            if len(idx) != n:
                cams = cams.subset(idx)
        elif max(cams.K.shape[0], cams.w2c.shape[0]) != len(idx):
            raise ValueError(
                f"{camera}: per-frame cameras do not match {n} video frames ({len(idx)} selected)"
            )
    return cams


def _frames(src: Path, wanted: set[int], alpha: bool, mask_video, mask_files):
    """(RGB image, mask) of the ``wanted`` frames. Both decoders close (ending their ffmpeg processes)
    when this generator stops, also on an error: an exception's traceback would otherwise keep them
    running as long as it is kept."""
    with ExitStack() as stack:
        masks = stack.enter_context(closing(read_frames(mask_video, False))) if mask_video is not None else None
        video = stack.enter_context(closing(read_frames(src, alpha)))
        yield from _selected(src, video, masks, wanted, alpha, mask_video, mask_files)


def _selected(src: Path, video, masks, wanted: set[int], alpha: bool, mask_video, mask_files):
    for i, img in enumerate(video):
        m = next(masks) if masks is not None else None
        if i not in wanted:
            continue
        if alpha:
            if img.shape[2] != 4:
                raise ValueError(f"{src}: the decoder returned no alpha channel")
            mask = img[..., 3].astype(np.float32) / 255.0
            if mask.min() == 1.0:
                raise ValueError(
                    f"{src}: frame {i} alpha is fully opaque; this video has no usable alpha"
                )
        elif m is not None:
            mask = mask_from_array(m, mask_video)
        else:
            mask = mask_from_array(iio.imread(mask_files[i]), mask_files[i])
        yield np.ascontiguousarray(img[..., :3]), mask
