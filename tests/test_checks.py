"""Finite values and stated ranges: the one check every reader and writer uses (gma.core.checks), the
body's parameter ranges, the edit limits, and the writers that refuse NaN (nothing is written)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import torch

from gma.core.checks import non_finite_problem, require_finite, require_in_range
from gma.core.errors import InputError, NonFiniteError


@pytest.mark.parametrize("values,words", [
    (np.zeros(4), None),
    (np.arange(5), None),  # integers are finite by construction
    (np.array([1.0, np.nan, np.nan]), "2 NaN values"),
    (np.array([np.inf]), "1 infinite value"),
    (np.array([np.nan, -np.inf, np.inf]), "1 NaN and 2 infinite values"),
    (torch.tensor([0.0, float("nan")], dtype=torch.bfloat16), "1 NaN value"),
    ([1.0, float("inf")], "1 infinite value"),
])
def test_non_finite_problem_says_what_and_how_many(values, words):
    assert non_finite_problem(values) == words


def test_require_finite_names_the_first_bad_entry():
    named = {"f_geo": torch.zeros(3), "f_tex": torch.full((4, 2), float("nan")), "shape": torch.full((2,), math.inf)}
    with pytest.raises(InputError, match=r"^avatar.gma: f_tex holds 8 NaN values$"):
        require_finite(named, "avatar.gma")
    with pytest.raises(NonFiniteError, match="shape holds 2 infinite values"):
        require_finite({"shape": named["shape"]}, "x", NonFiniteError)
    require_finite({"f_geo": named["f_geo"]}, "x")


@pytest.mark.parametrize("value,ok", [(0.0, False), (1e-9, True), (4.0, True), (4.1, False), (math.nan, False),
                                      (math.inf, False), ("abc", False)])
def test_require_in_range(value, ok):
    if ok:
        assert require_in_range("--size", value, 0.0, 4.0, "m", low_open=True) == value
    else:
        with pytest.raises(InputError, match=r"--size: must "):
            require_in_range("--size", value, 0.0, 4.0, "m", low_open=True)


def test_param_space_check_values_names_entry_and_range():
    from gma.body.base import ParamSpace

    space = ParamSpace("shape", ("gender", "age"), (), np.full(2, 0.5, np.float32), np.zeros(2, np.float32),
                       np.ones(2, np.float32))
    space.check_values(torch.tensor([0.0, 1.0]))
    with pytest.raises(ValueError, match=r"shape entry 'age' is nan, not a finite number in \[0, 1\]"):
        space.check_values(torch.tensor([0.5, float("nan")]))
    with pytest.raises(ValueError, match=r"shape entry 'gender' is 5, not a finite number in \[0, 1\]"):
        space.check_values(torch.tensor([5.0, 0.5]))
    with pytest.raises(ValueError, match="must have shape"):
        space.check_values(torch.tensor([0.5]))
    free = ParamSpace("transl", ("x",), (), np.zeros(1, np.float32))  # no declared range: finite is enough
    free.check_values(torch.tensor([1e6]))
    with pytest.raises(ValueError, match="not a finite number"):
        free.check_values(torch.tensor([math.inf]))


def test_edit_limits():
    from gma.edit import EditError, StampPlacement

    assert StampPlacement.parse_size("15cm") == pytest.approx((0.15, "m"))
    for text in ("1e9m", "infm", "nanm", "-3cm", "0px", "99999px"):
        with pytest.raises(EditError, match="--size"):
            StampPlacement.parse_size(text, "--size")
    with pytest.raises(EditError, match=r"stamp rotation: must lie in \[-360, 360\] degrees"):
        StampPlacement(None, 0.1, "m", float("nan"))
    with pytest.raises(EditError, match="stamp centre"):
        StampPlacement((1.0, float("inf")), 0.1, "m")


def test_fit_options_must_be_finite():
    from gma.train.config import preset

    with pytest.raises(ValueError, match=r"--lr-features: must be a finite number >= 0, got nan"):
        preset("quick", lr_features=float("nan"))
    with pytest.raises(ValueError, match=r"--weights2.l1: must be a finite number >= 0, got -1"):
        preset("quick", weights2={"l1": -1.0})


def test_checkpoint_with_nan_is_not_written(tmp_path):
    from gma.train.checkpoint import load_checkpoint, save_checkpoint

    net = torch.nn.Linear(3, 2)
    opt = torch.optim.Adam(net.parameters())
    path = tmp_path / "checkpoint.safetensors"
    save_checkpoint(path, net, opt, {"step": 1})
    good = path.read_bytes()
    with torch.no_grad():
        net.weight[0, 0] = float("nan")
    with pytest.raises(NonFiniteError, match="checkpoint.safetensors: not written: model.weight holds 1 NaN value"):
        save_checkpoint(path, net, opt, {"step": 2})
    assert path.read_bytes() == good  # the last good checkpoint stays
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    load_checkpoint(path, net, lambda meta: torch.optim.Adam(net.parameters()))
    assert torch.isfinite(net.weight).all()


@pytest.mark.filterwarnings("error")  # an overflow warning would be a second line to the user
def test_splat_ply_with_nan_is_neither_written_nor_read(tmp_path):
    from gma.render.ply import load_splat_ply, save_splat_ply

    n = 3
    splat = dict(means=np.zeros((n, 3)), quats=np.tile([1.0, 0, 0, 0], (n, 1)), scales=np.full((n, 2), 0.01),
                 opacities=np.full(n, 0.5), colors=np.full((n, 3), 0.5))
    save_splat_ply(tmp_path / "ok.ply", **splat)
    bad = dict(splat, means=np.where(np.eye(n, 3) > 0, np.nan, 0.0))
    with pytest.raises(NonFiniteError, match="bad.ply: not written: the splat data holds 3 NaN values"):
        save_splat_ply(tmp_path / "bad.ply", **bad)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ok.ply"]
    # A quaternion of NaN used to become the identity silently.
    data = bytearray((tmp_path / "ok.ply").read_bytes())
    header_end = data.index(b"end_header\n") + len(b"end_header\n")
    props = [line.split()[-1] for line in data[:header_end].decode().splitlines() if line.startswith("property")]
    row = np.frombuffer(data, "<f4", count=len(props) * n, offset=header_end).reshape(n, -1).copy()
    row[1, props.index("rot_2")] = np.nan
    (tmp_path / "nan.ply").write_bytes(bytes(data[:header_end]) + row.tobytes())
    with pytest.raises(InputError, match=r"nan.ply: property 'rot_2' holds 1 NaN value"):
        load_splat_ply(tmp_path / "nan.ply")
    row[1, props.index("rot_2")] = 0.0
    row[0, props.index("scale_0")] = 500.0  # finite, but exp(500) overflows float32
    (tmp_path / "big.ply").write_bytes(bytes(data[:header_end]) + row.tobytes())
    with pytest.raises(InputError, match=r"big.ply: values too large: scales \(activated\) holds 1 infinite"):
        load_splat_ply(tmp_path / "big.ply")


def test_avatar_with_nan_is_neither_saved_nor_loaded(tmp_path, anny_body):
    from gma.avatar import Avatar, AvatarConfig
    from gma.avatar.avatar import AvatarFileError

    avatar = Avatar.create(AvatarConfig(feature_dim=4, fine_per_face=1), anny_body)
    path = avatar.save(tmp_path / "a.gma")
    good = path.read_bytes()
    with torch.no_grad():
        avatar.model.f_tex[:5] = float("nan")
    with pytest.raises(NonFiniteError, match=r"a.gma: not written: f_tex holds 20 NaN values"):
        avatar.save(path)
    assert path.read_bytes() == good and sorted(p.name for p in tmp_path.iterdir()) == ["a.gma"]
    with torch.no_grad():
        avatar.model.f_tex[:5] = 0.0
    avatar.info["expression"] = [float("nan")] * 52
    with pytest.raises(NonFiniteError, match="the expression holds 52 NaN values"):
        avatar.save(path)
    # The same file written past the check (another tool): refused on reading, naming the tensor.
    avatar.info.pop("expression")
    with torch.no_grad():
        avatar.model.f_geo[0, 0] = float("inf")
    from safetensors.torch import save

    from gma.avatar.avatar import canonical_safetensors

    tensors = {f"model.{k}": v.detach().contiguous() for k, v in avatar.model.state_dict().items()}
    tensors |= {"rest_vertices": avatar.rest_vertices.contiguous(), "shape": avatar.shape.contiguous()}
    meta = {"format": "gma", "version": "1", "body": "anny", "config": json.dumps(avatar.config.to_dict()),
            "history": "[]", "info": "{}"}
    (tmp_path / "inf.gma").write_bytes(canonical_safetensors(save(tensors, metadata=meta)))
    with pytest.raises(AvatarFileError, match=r"inf.gma: f_geo holds 1 infinite value"):
        Avatar.load(tmp_path / "inf.gma", anny_body)
