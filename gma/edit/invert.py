"""Inverting the frozen decoders: per-face features whose decoded outputs match targets.

Paint, stamp and cross-shape transfer all reduce to one problem per touched face f: find a feature x
(length k) minimising

    Σ_heads w_h ‖MLP_h([x, PE_f]) − y_h‖²  +  λ ‖x − a‖²

where the heads are raw decoder outputs (before the output activations: colour logits for T_color,
pre-softplus scales for T_scale, barycentric logits and pre-tanh offsets for F_fine, corner scales for
F_coarse), y_h the targets and a an anchor feature (the old one, or the donor's).

Method: batched damped Gauss–Newton (Levenberg–Marquardt), all faces at once. Why: the decoders are
two-layer MLPs, so the Jacobian of a head w.r.t. x is exact and cheap in closed form,
J = W2 · diag(act'(W1 [x, PE] + b1)) · W1[:, :k]; for ReLU heads (T_color, T_scale) the objective is
piecewise quadratic and a GN step lands on the minimum of the current linear region, so a handful of
steps converge where Adam needs hundreds. Targets are matched in the raw (pre-activation) space, where
the heads are piecewise linear; colour targets are clamped to [margin, 1 − margin] first, the range the
sigmoid reaches with finite logits. k is small (32), so the k×k normal equations of all faces are one
batched Cholesky solve. λ keeps the feature near the anchor in directions the outputs do not fix
(k exceeds the number of outputs) and makes every system positive definite.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch
from torch import nn

__all__ = ["Head", "InvertConfig", "mlp_jacobian", "solve_features"]


@dataclass
class InvertConfig:
    """Settings of the Gauss–Newton feature solve."""

    iterations: int = 25  # cap on steps; most faces converge in fewer and leave the working set
    regularization: float = 1e-3  # λ: pull towards the anchor feature
    damping: float = 1e-3  # initial Levenberg–Marquardt damping (adapted per face)
    scale_weight: float = 4.0  # weight of T_scale's residual against the colour logits' (paint keeps scales)
    margin: float = 0.01  # colour targets are clamped to [margin, 1 - margin] (reachable sigmoid range)
    tolerance: float = 1e-3  # a face is done when a step lowers its cost by less than this fraction
    rms_tolerance: float = 0.03  # ... or when its residual RMS per output is below this (raw units:
    #                             0.03 of a colour logit is under 0.008 of colour)


@dataclass
class Head:
    """One decoder head in a solve: ``mlp`` (an ``Mlp``), ``target`` [M, O] raw outputs to match,
    ``weight`` a scalar or [M, O] per-output weight (0 frees an output)."""

    mlp: nn.Sequential
    target: torch.Tensor
    weight: float | torch.Tensor = 1.0


def _act_grad(act: nn.Module, h: torch.Tensor) -> torch.Tensor:
    if isinstance(act, nn.ReLU):
        return (h > 0).to(h.dtype)
    if isinstance(act, nn.GELU) and act.approximate == "none":
        cdf = 0.5 * (1 + torch.erf(h / math.sqrt(2)))
        return cdf + h * torch.exp(-0.5 * h * h) / math.sqrt(2 * math.pi)
    raise TypeError(f"no closed-form derivative for {act}")


def mlp_jacobian(mlp: nn.Sequential, x: torch.Tensor, k: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Outputs [M, O] of a Linear-act-Linear ``mlp`` at inputs ``x`` [M, k + P], and their Jacobian
    [M, O, k] with respect to the first ``k`` inputs (the feature; the PE is fixed)."""
    lin1, act, lin2 = mlp[0], mlp[1], mlp[2]
    h = lin1(x)
    out = lin2(act(h))
    dh = _act_grad(act, h)  # [M, H]
    # W2 · diag(dh) · W1k for every face as one GEMM: scale W2's columns per face ([M·O, H]), then · W1k.
    m, o, hid = h.shape[0], lin2.weight.shape[0], h.shape[1]
    jac = ((dh[:, None, :] * lin2.weight).reshape(m * o, hid) @ lin1.weight[:, :k]).reshape(m, o, k)
    return out, jac


def _select(heads: list[Head], idx: torch.Tensor) -> list[Head]:
    return [Head(h.mlp, h.target[idx], h.weight[idx] if torch.is_tensor(h.weight) and h.weight.dim() else h.weight)
            for h in heads]


def _cost(heads: list[Head], x, pe, anchor, lam) -> tuple[torch.Tensor, torch.Tensor]:
    inp = torch.cat([x, pe], -1)
    total = lam * (x - anchor).square().sum(-1)
    for h in heads:
        total = total + (h.weight * (h.mlp(inp) - h.target).square()).sum(-1)
    return total, inp


@torch.no_grad()
def solve_features(heads: list[Head], x0: torch.Tensor, pe: torch.Tensor, anchor: torch.Tensor,
                   config: InvertConfig | None = None) -> tuple[torch.Tensor, dict]:
    """Features [M, k] minimising the objective of the module doc, starting from ``x0`` [M, k]; ``pe``
    [M, P] the faces' positional encodings, ``anchor`` [M, k]. Returns (x, info) with info["iterations"]
    (steps taken by the slowest face), info["steps"] (face-steps in all, the work done) and info["cost"]
    [M] (final per-face cost).

    Faces leave the working set once a step gains less than ``tolerance`` of their cost (or their
    damping has grown past use), so late iterations only pay for the few faces still moving."""
    cfg = config or InvertConfig()
    m, k = x0.shape
    x = x0.clone()
    if m == 0:
        return x, {"iterations": 0, "steps": 0, "cost": torch.zeros(0)}
    lam = cfg.regularization
    mu = torch.full((m,), cfg.damping)
    eye = torch.eye(k)
    cost, _ = _cost(heads, x, pe, anchor, lam)
    outputs = sum(h.target.shape[1] for h in heads)
    good = cfg.rms_tolerance**2 * outputs
    active = torch.nonzero(cost > good).reshape(-1)
    it = steps = 0
    while len(active) and it < cfg.iterations:
        it += 1
        steps += len(active)
        hs, xa, pa, aa, ma = _select(heads, active), x[active], pe[active], anchor[active], mu[active]
        inp = torch.cat([xa, pa], -1)
        n = len(active)
        jtj = (lam * eye).expand(n, k, k).clone()
        grad = lam * (xa - aa)
        for h in hs:
            out, jac = mlp_jacobian(h.mlp, inp, k)
            w = torch.as_tensor(h.weight, dtype=x.dtype)
            wj = jac * (w.unsqueeze(-1) if w.dim() else w)
            jtj += torch.matmul(wj.transpose(1, 2), jac)
            grad += torch.matmul(wj.transpose(1, 2), (out - h.target).unsqueeze(-1)).squeeze(-1)
        chol, bad = torch.linalg.cholesky_ex(jtj + ma[:, None, None] * eye)
        step = -torch.cholesky_solve(grad.unsqueeze(-1), chol).squeeze(-1)
        step[bad > 0] = 0
        new_cost, _ = _cost(hs, xa + step, pa, aa, lam)
        old_cost = cost[active]
        better = new_cost < old_cost
        gain = (old_cost - new_cost) / old_cost.clamp_min(1e-20)
        x[active] = torch.where(better[:, None], xa + step, xa)
        cost[active] = torch.where(better, new_cost, old_cost)
        mu[active] = torch.where(better, ma / 3, ma * 4).clamp(1e-9, 1e6)
        done = (better & (gain < cfg.tolerance)) | (mu[active] >= 1e6) | (cost[active] <= good)
        active = active[~done]
    return x, {"iterations": it, "steps": steps, "cost": cost}
