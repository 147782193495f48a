"""Atomic training checkpoints (safetensors: model + Adam state; JSON metadata: step, stage, history).
No pickle: ``torch.save`` would make a checkpoint an executable file."""

from __future__ import annotations

import json
from pathlib import Path

import torch
from safetensors import safe_open
from safetensors.torch import load_file, save

from gma.core.atomic import atomic_write_bytes
from gma.core.checks import require_finite
from gma.core.errors import NonFiniteError

__all__ = ["load_checkpoint", "save_checkpoint"]


def _unique_state(model: torch.nn.Module) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    """(state dict without repeats, {repeated key: the key stored}). Avatars fitted together share their
    decoder modules, so one tensor appears under several names; safetensors stores each tensor once."""
    first: dict[int, str] = {}
    unique, aliases = {}, {}
    for key, value in model.state_dict().items():
        ptr = value.data_ptr()
        if ptr in first:
            aliases[key] = first[ptr]
        else:
            first[ptr] = key
            unique[key] = value
    return unique, aliases


def save_checkpoint(path: Path, model: torch.nn.Module, optimizer: torch.optim.Optimizer, meta: dict) -> None:
    """Write model parameters, the optimiser's per-parameter state and ``meta`` (JSON-able) atomically.
    A NaN or infinity anywhere raises :class:`NonFiniteError` and leaves the previous checkpoint (the last
    good one) in place."""
    tensors = {f"model.{k}": v.detach().contiguous() for k, v in _unique_state(model)[0].items()}
    state = optimizer.state_dict()
    for pid, st in state["state"].items():
        for name, value in st.items():
            t = value if isinstance(value, torch.Tensor) else torch.tensor(value)
            tensors[f"opt.{pid}.{name}"] = t.detach().contiguous()
    meta = {**meta, "param_groups": [{k: v for k, v in g.items() if k != "params"} | {"params": g["params"]}
                                     for g in state["param_groups"]]}
    require_finite(tensors, f"{path}: not written", NonFiniteError)
    atomic_write_bytes(path, save(tensors, metadata={"meta": json.dumps(meta)}))


def load_checkpoint(path: Path, model: torch.nn.Module, optimizer_factory) -> tuple[torch.optim.Optimizer, dict]:
    """Restore ``model`` from ``path``; ``optimizer_factory(meta)`` builds the optimiser of the stage the
    checkpoint was in, whose state is then restored. Returns (optimizer, meta)."""

    try:
        tensors = load_file(str(path))
        with safe_open(str(path), "pt") as f:
            meta = json.loads(f.metadata()["meta"])
    except Exception as exc:  # a damaged checkpoint must say which file
        raise ValueError(f"{path}: unreadable checkpoint ({exc}); delete it to start over") from exc
    require_finite(tensors, f"{path}: damaged checkpoint (delete it to start over)", ValueError)
    state = {k[6:]: v for k, v in tensors.items() if k.startswith("model.")}
    for alias, stored in _unique_state(model)[1].items():
        if stored in state:
            state[alias] = state[stored]
    try:
        model.load_state_dict(state)
    except RuntimeError as exc:
        raise ValueError(f"{path}: checkpoint does not match this fit ({exc}); delete it to start over") from exc
    opt = optimizer_factory(meta)
    state: dict = {}
    for key, value in tensors.items():
        if key.startswith("opt."):
            _, pid, name = key.split(".", 2)
            state.setdefault(int(pid), {})[name] = value
    opt.load_state_dict({"state": state, "param_groups": meta["param_groups"]})
    return opt, meta
