"""The one camera JSON parser (gma.core.camera.parse_camera_json): a sequence's cameras.json
(gma.data.load_cameras) and a single --camera file (Camera.load) follow the same rules and give the same
one-line messages naming the file; a good file round-trips."""

from __future__ import annotations

import json

import numpy as np
import pytest

from gma.core.camera import Camera, parse_camera_json
from gma.core.errors import InputError, MissingFileError
from gma.data import load_cameras

GOOD = {"width": 48, "height": 32, "K": [[40.0, 0, 24], [0, 40.0, 16], [0, 0, 1]], "w2c": np.eye(4).tolist()}


def _with(**changes):
    out = dict(GOOD, **changes)
    return {k: v for k, v in out.items() if v is not None}


BAD = {
    "not an object": ([1, 2], "expected a JSON object"),
    "no w2c": (_with(w2c=None), "missing 'w2c'"),
    "no K": (_with(K=None), "missing 'K'"),
    "width as text": (_with(width="48"), "'width' must be a positive integer"),
    "fractional height": (_with(height=31.5), "'height' must be a positive integer"),
    "zero width": (_with(width=0), "'width' must be a positive integer"),
    "K 2x2": (_with(K=[[1, 0], [0, 1]]), "'K' has shape [2, 2]"),
    "K of text": (_with(K="identity"), "'K' is not a numeric array"),
    "NaN in K": (_with(K=[[float("nan"), 0, 24], [0, 40, 16], [0, 0, 1]]), "'K' holds a non-finite value"),
    "negative focal": (_with(K=[[-40.0, 0, 24], [0, 40.0, 16], [0, 0, 1]]), "focal lengths must be positive"),
    "K last row": (_with(K=[[40.0, 0, 24], [0, 40.0, 16], [0, 1, 1]]), "'K' last row must be [0, 0, 1]"),
    "w2c last row": (_with(w2c=[[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 1, 1]]),
                     "'w2c' last row must be [0, 0, 0, 1]"),
    "scaled w2c": (_with(w2c=(np.eye(4) * [2, 2, 2, 1]).tolist()), "not a proper rotation"),
    "mirrored w2c": (_with(w2c=np.diag([1.0, 1.0, -1.0, 1.0]).tolist()), "not a proper rotation"),
}


@pytest.mark.parametrize("name", list(BAD))
def test_bad_camera_files_give_the_same_line_to_both_readers(tmp_path, name):
    data, message = BAD[name]
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(data))
    for read in (Camera.load, load_cameras):
        with pytest.raises(InputError) as info:
            read(path)
        text = str(info.value)
        assert text.startswith(str(path)) and message in text and "\n" not in text, text


def test_missing_and_unreadable_files(tmp_path):
    for read in (Camera.load, load_cameras):
        with pytest.raises(MissingFileError, match="camera file not found"):
            read(tmp_path / "none.json")
    (tmp_path / "broken.json").write_text("{")
    for read in (Camera.load, load_cameras):
        with pytest.raises(InputError, match=r"broken\.json: not valid JSON"):
            read(tmp_path / "broken.json")


def test_per_frame_cameras_and_frame_counts(tmp_path):
    stack = _with(w2c=[np.eye(4).tolist()] * 3)
    path = tmp_path / "cams.json"
    path.write_text(json.dumps(stack))
    cams = load_cameras(path, num_frames=3)
    assert cams.K.shape == (1, 3, 3) and cams.w2c.shape == (3, 4, 4) and not cams.static
    with pytest.raises(InputError, match="'w2c' has 3 per-frame entries but the sequence has 2 frames"):
        load_cameras(path, num_frames=2)
    with pytest.raises(InputError, match="3 per-frame cameras; one camera expected"):
        Camera.load(path)


def test_round_trip_of_a_good_camera(tmp_path):
    cam = Camera.look_at((0.5, 1.0, 3.0), (0.0, 1.0, 0.0), width=40, height=30)
    path = tmp_path / "cam.json"
    path.write_text(json.dumps(cam.to_json()))
    back = Camera.load(path)
    assert (back.width, back.height) == (40, 30)
    np.testing.assert_allclose(back.K, cam.K)
    np.testing.assert_allclose(back.viewmat, cam.viewmat)
    width, height, K, w2c = parse_camera_json(cam.to_json(), "cam")
    assert (width, height, K.shape, w2c.shape) == (40, 30, (1, 3, 3), (1, 4, 4)) and K.dtype == np.float64
