"""``gma edit``: a paint, history and undo through the command line, and every bad input one line on
stderr, exit code 2, nothing written."""

from __future__ import annotations

import json

import numpy as np
import pytest
from edit_helpers import fitted_avatar

from gma.cli import main


@pytest.fixture(scope="module")
def files(anny_body, tmp_path_factory):
    d = tmp_path_factory.mktemp("edit_cli")
    fitted_avatar(anny_body).save(d / "in.gma")
    from gma.avatar import Avatar, AvatarConfig

    Avatar.create(AvatarConfig(feature_dim=8, fine_per_face=2, hidden=64), anny_body).save(d / "other.gma")
    (d / "bad.png").write_bytes(b"not a png")
    away = {"width": 64, "height": 64, "K": [[50, 0, 32], [0, 50, 32], [0, 0, 1]],
            "w2c": [[1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, -5], [0, 0, 0, 1]]}  # the body is behind it
    (d / "away.json").write_text(json.dumps(away))
    return d


def test_paint_history_undo(files, capsys):
    src, out, back = files / "in.gma", files / "painted.gma", files / "undone.gma"
    assert main(["edit", str(src), "-o", str(out), "--select", "region:torso", "--paint", "#c03030"]) == 0
    assert main(["edit", str(out), "--history"]) == 0
    listing = capsys.readouterr().out
    assert "paint" in listing and "faces" in listing
    assert main(["edit", str(out), "-o", str(back), "--undo", "1"]) == 0
    assert back.read_bytes() == src.read_bytes()


def test_stamp_shape_and_body(files):
    out = files / "stamped.gma"
    assert main(["edit", str(files / "in.gma"), "-o", str(out), "--stamp", "shape:circle", "--color", "red",
                 "--size", "0.2m", "--view-size", "128", "--shape", "0.5,0.5,0.5,0.5,0.7,0.5"]) == 0
    from gma.avatar import Avatar

    av = Avatar.load(out)
    assert [r["op"] for r in av.history] == ["stamp", "body"]
    assert np.allclose(av.shape.numpy(), [0.5, 0.5, 0.5, 0.5, 0.7, 0.5])


def test_mirror_paints_both_hands(files, capsys):
    from gma.avatar import Avatar

    out = files / "mirrored.gma"
    assert main(["edit", str(files / "in.gma"), "-o", str(out), "--select", "region:hand.L", "--mirror",
                 "--paint", "#2040c0"]) == 0
    record = Avatar.load(out).history[0]
    assert record["op"] == "paint" and record["faces"] == 2 * 3196  # both hands (3196 faces each), nothing else
    assert "painted 6392 faces" in capsys.readouterr().out


@pytest.mark.parametrize("extra,message", [
    (["--select", "region:elbows", "--paint", "red"], "unknown body region 'elbows'"),
    (["--select", "box:front@0,0,2,2", "--paint", "red"], "empty"),
    (["--select", "region:torso", "--paint", "#12345"], "cannot parse colour"),
    (["--stamp", "{d}/bad.png"], "cannot read stamp image"),
    (["--stamp", "{d}/missing.png"], "does not exist"),
    (["--select", "region:torso", "--transfer", "{d}/other.gma"], "gma fit --decoders"),
    (["--stamp", "shape:circle", "--camera", "{d}/away.json"], "sees no face"),
    (["--select", "wand:front@1,1", "--paint", "red"], "shows no face"),
    (["--select", "nothing.txt", "--paint", "red"], "cannot read selection"),
    (["--paint", "red"], "need --select"),
    (["--undo", "3"], "holds 0 records"),
    (["--stamp", "shape:circle", "--mirror"], "--mirror applies to --paint and --transfer"),
    ([], "nothing to do"),
])
def test_bad_input_one_line_exit_2(files, capsys, extra, message):
    out = files / "never.gma"
    argv = ["edit", str(files / "in.gma"), "-o", str(out), "--view-size", "128"]
    argv += [a.format(d=files) for a in extra]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and message in err, err
    assert not out.exists()


def test_refuses_to_overwrite_input(files, capsys):
    src = files / "in.gma"
    before = src.read_bytes()
    assert main(["edit", str(src), "-o", str(src), "--select", "region:hands", "--paint", "red"]) == 2
    assert "--force" in capsys.readouterr().err
    assert src.read_bytes() == before


def test_refuses_to_replace_an_existing_output_without_force(files, capsys):
    out = files / "kept.gma"
    out.write_bytes(b"the user's own file")
    argv = ["edit", str(files / "in.gma"), "-o", str(out), "--select", "region:hands", "--paint", "red"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--force" in err
    assert out.read_bytes() == b"the user's own file"
    assert main(argv + ["--force"]) == 0
    assert main(argv + ["--overwrite"]) == 0  # the old name still works


def _stamped_faces(files, out, *select_and_stamp):
    from gma.avatar import Avatar

    argv = ["edit", str(files / "in.gma"), "-o", str(out), "--view", "front", "--view-size", "128",
            "--stamp", "shape:circle", "--color", "#2040c0", *select_and_stamp]
    assert main(argv) == 0
    record = Avatar.load(out).history[-1]
    assert record["op"] == "stamp"
    return record


@pytest.mark.parametrize("case", ["selection_larger_than_footprint", "selection_smaller_than_footprint"])
def test_stamp_into_a_selection(files, case):
    """The selection's weights follow the faces the footprint keeps, whichever of the two is larger."""
    from gma.avatar import Avatar
    from gma.body import load_body
    from gma.edit import Selection

    before = Avatar.load(files / "in.gma")
    out = files / f"{case}.gma"
    if case == "selection_larger_than_footprint":
        region, size = "torso", "0.1m"
    else:
        region, size = "head", "1m"
    _stamped_faces(files, out, "--select", f"region:{region}", "--size", size)
    after = Avatar.load(out)
    changed = (after.model.f_tex != before.model.f_tex).any(1).nonzero().reshape(-1)
    inside = set(Selection.from_regions(load_body(before.body_name), region).faces.tolist())
    assert len(changed) > 0 and set(changed.tolist()) <= inside
    if case == "selection_larger_than_footprint":
        assert len(changed) < 0.5 * len(inside)


def test_stamp_that_misses_the_selection_is_one_line(files, capsys):
    out = files / "missed.gma"
    argv = ["edit", str(files / "in.gma"), "-o", str(out), "--view", "front", "--view-size", "128",
            "--stamp", "shape:circle", "--select", "region:hand.L", "--at", "64,10", "--size", "10px"]
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "covers no visible surfel of the selection" in err, err
    assert not out.exists()
