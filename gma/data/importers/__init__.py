"""Importers from public dataset layouts and from video into the sequence format.

Each ``import_*`` function validates its source, fails early with a clear message when the user's
SMPL / SMPL-X model files are needed but absent, and writes the sequence atomically.
"""

from gma.data.importers.peoplesnapshot import import_peoplesnapshot
from gma.data.importers.video import import_video
from gma.data.importers.xhumans import import_xhumans
from gma.data.importers.zjumocap import import_zjumocap

IMPORTERS = {
    "peoplesnapshot": import_peoplesnapshot,
    "xhumans": import_xhumans,
    "zjumocap": import_zjumocap,
    "video": import_video,
}

__all__ = ["IMPORTERS", "import_peoplesnapshot", "import_video", "import_xhumans", "import_zjumocap"]
