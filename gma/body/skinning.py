"""Linear-blend skinning in torch: the reference for ``shaders/wgsl/body/skin.wgsl`` and the path
training differentiates through."""

from __future__ import annotations

import torch

__all__ = ["dense_to_sparse_weights", "linear_blend_skinning"]


def linear_blend_skinning(
    rest_vertices: torch.Tensor,  # [..., V, 3]
    skin_indices: torch.Tensor,  # [V, K] int
    skin_weights: torch.Tensor,  # [V, K]
    bone_transforms: torch.Tensor,  # [..., J, 4, 4]
) -> torch.Tensor:
    """Posed vertices ``Σ_k w_vk · T[i_vk] · [v, 1]`` → [..., V, 3].

    Sparse (K influences per vertex) rather than dense [V, J] weights: K ≪ J (Anny: 9 of 104, SMPL-X
    usually ≤ 4 non-zero), and the GPU kernel reads the same layout. Differentiable w.r.t. the rest
    vertices, the weights and the transforms.
    """
    if rest_vertices.shape[-1] != 3:
        raise ValueError(f"rest_vertices must be [..., V, 3], got {tuple(rest_vertices.shape)}")
    if bone_transforms.shape[-2:] != (4, 4):
        raise ValueError(f"bone_transforms must be [..., J, 4, 4], got {tuple(bone_transforms.shape)}")
    if skin_indices.shape != skin_weights.shape or skin_indices.shape[0] != rest_vertices.shape[-2]:
        raise ValueError(
            f"skin_indices {tuple(skin_indices.shape)} and skin_weights {tuple(skin_weights.shape)} must "
            f"both be [V, K] with V = {rest_vertices.shape[-2]}"
        )
    top = bone_transforms[..., :3, :]  # [..., J, 3, 4]; the bottom row of a rigid transform is constant
    gathered = top[..., skin_indices, :, :]  # [..., V, K, 3, 4]
    blended = (skin_weights[..., None, None].to(top.dtype) * gathered).sum(-3)  # [..., V, 3, 4]
    return (blended[..., :3] @ rest_vertices[..., None]).squeeze(-1) + blended[..., 3]


def dense_to_sparse_weights(dense: torch.Tensor, k: int | None = None) -> tuple[torch.Tensor, torch.Tensor]:
    """Dense [V, J] weights → (indices [V, K] int64, weights [V, K]) keeping the K largest per vertex.

    With ``k=None`` K is the largest number of non-zero weights of any vertex, so nothing is lost.
    Dropped weight (when ``k`` is smaller) is renormalised so each row still sums to its original sum.
    """
    if dense.dim() != 2:
        raise ValueError(f"dense weights must be [V, J], got {tuple(dense.shape)}")
    if k is None:
        k = max(1, int((dense != 0).sum(1).max().item())) if dense.numel() else 1
    k = min(k, dense.shape[1])
    weights, indices = torch.topk(dense, k, dim=1)
    total = dense.sum(1, keepdim=True)
    kept = weights.sum(1, keepdim=True)
    weights = torch.where(kept > 0, weights * (total / kept.clamp_min(1e-12)), weights)
    return indices.long(), weights
