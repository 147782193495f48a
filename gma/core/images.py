"""Reading users' image files."""

from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np


def read_image(path: str | Path) -> np.ndarray:
    """``imageio.v3.imread``, quietly. For a file that no plugin reads, imageio tries its legacy plugins
    too, and two of them (tifffile, DICOM) warn that they are deprecated; the callers report the failure
    themselves, in one line, so those warnings would only be noise. (``catch_warnings`` changes process
    state: GMA reads no image from a thread.)"""
    import imageio.v3 as iio

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        return iio.imread(path)
