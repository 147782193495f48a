"""``gma body info`` / ``gma body export-obj``."""

from __future__ import annotations

from gma.cli import main


def test_body_info(anny_body, capsys):
    assert main(["body", "info"]) == 0
    out = capsys.readouterr().out
    assert "J=104" in out and "expression: 52" in out and "upper_body" in out


def test_export_obj(anny_body, tmp_path):
    out = tmp_path / "walk.obj"
    assert main(["body", "export-obj", str(out), "--motion", "walk", "--frame", "3", "--frames", "10"]) == 0
    lines = out.read_text().splitlines()
    assert sum(line.startswith("v ") for line in lines) == anny_body.num_vertices
    assert sum(line.startswith("vt ") for line in lines) == 3 * anny_body.num_faces
    assert sum(line.startswith("f ") for line in lines) == anny_body.num_faces


def test_smplx_without_files_is_one_clear_line(tmp_path, monkeypatch, capsys):
    monkeypatch.delenv("GMA_SMPLX_DIR", raising=False)
    assert main(["body", "info", "--model", "smplx", "--smplx-dir", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "SMPLX_NEUTRAL.npz" in err and "smpl-x.is.tue.mpg.de" in err
