"""From a raw video of a person to a sequence: MediaPipe masks and landmarks (optional extra
``gma[video]``), a static pinhole camera, an Anny body fit, and a report with a contact sheet.

::

    from gma.video import estimate_sequence, VideoImportConfig
    seq, report = estimate_sequence("clip.mp4", "seq_out", config=VideoImportConfig(focal=1200))

Nothing here imports MediaPipe, torch models or a GPU at import time.
"""

from gma.video.detect import Detections, MissingExtraError, detect_frames, require_mediapipe
from gma.video.fit import FitConfig, FitResult, fit_body
from gma.video.frames import VideoError, read_video
from gma.video.pipeline import VideoImportConfig, estimate_sequence, work_dir

__all__ = [
    "Detections",
    "FitConfig",
    "FitResult",
    "MissingExtraError",
    "VideoError",
    "VideoImportConfig",
    "detect_frames",
    "estimate_sequence",
    "fit_body",
    "read_video",
    "require_mediapipe",
    "work_dir",
]
