"""Input sequences: the on-disk format (read with validation, written atomically), the synthetic
ground-truth generator, importers for public dataset layouts, and video import.

What the fitting code calls::

    from gma.data import read_sequence
    seq = read_sequence("path/to/seq")          # validates everything up front
    for i in seq.split("train"):
        rgb = seq.image(i)                      # uint8 [H, W, 3]
        alpha = seq.mask(i)                     # float32 [H, W] in [0, 1]
        K, w2c = seq.cameras.frame(i)           # [3, 3], [4, 4] OpenCV world->camera
        params = seq.body.frame(i)              # dict of arrays, see gma.body.params
"""

from gma.body.params import BODY_MODELS, SequenceBody, find_model_file, load_body, save_body
from gma.data.cameras import Cameras, load_cameras, look_at, save_cameras
from gma.data.sequence import SPLIT_KEYS, Sequence, SequenceWriter, read_sequence

__all__ = [
    "BODY_MODELS",
    "SPLIT_KEYS",
    "SequenceBody",
    "Cameras",
    "Sequence",
    "SequenceWriter",
    "find_model_file",
    "load_body",
    "load_cameras",
    "look_at",
    "read_sequence",
    "save_body",
    "save_cameras",
]
