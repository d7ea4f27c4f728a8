"""Midpoint trees as tensors, and their Monte-Carlo / TD(lambda) targets (Alg. 1, eq. 8).

A batch of ``B`` trees of depth ``D`` is stored by its final sequence
``points`` of shape ``(B, 2**D + 1, dim)``: level ``i`` of the tree is
``points[:, ::2**(D - i)]`` (``2**i + 1`` points, ``2**i`` adjacent pairs). Building a
tree costs one batched actor call per level; no Python loop over points.
"""

from __future__ import annotations

from collections.abc import Callable

import torch

from finsler.infra.limits import check_memory

__all__ = [
    "build_tree",
    "level_pairs",
    "mc_targets",
    "td_lambda_targets",
]


def build_tree(
    starts: torch.Tensor,
    goals: torch.Tensor,
    depth: int,
    predict: Callable[[torch.Tensor, torch.Tensor], torch.Tensor],
) -> torch.Tensor:
    """Recursive midpoint insertion: ``(B, dim)``, ``(B, dim)`` -> ``(B, 2**depth + 1, dim)``.

    ``predict(s, g)`` maps ``(N, dim)`` pairs to midpoints ``(N, dim)``; it is called once
    per level with all the level's adjacent pairs. Output dtype is that of ``starts``.
    """
    if starts.shape != goals.shape or starts.ndim != 2:
        raise ValueError(f"starts and goals must both be (B, dim), got {starts.shape}, "
                         f"{goals.shape}")
    b, dim = starts.shape
    check_memory((b, 2**depth + 1, dim), f"a midpoint tree of depth {depth} for {b} pairs",
                 hint="use a smaller depth or fewer pairs", copies=3)
    pts = torch.stack([starts, goals], 1)
    for _ in range(depth):
        n = pts.shape[1] - 1
        s = pts[:, :-1].reshape(-1, dim)
        g = pts[:, 1:].reshape(-1, dim)
        m = predict(s, g).to(pts.dtype).reshape(b, n, dim)
        new = pts.new_empty((b, 2 * n + 1, dim))
        new[:, 0::2] = pts
        new[:, 1::2] = m
        pts = new
    return pts


def level_pairs(points: torch.Tensor, level: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Adjacent pairs of level ``i`` of trees ``(B, 2**D + 1, dim)`` ->
    starts, goals ``(B, 2**i, dim)`` each."""
    depth = _depth_of(points)
    if not 0 <= level <= depth:
        raise ValueError(f"level must be in [0, {depth}], got {level}")
    step = 2 ** (depth - level)
    lv = points[:, ::step]
    return lv[:, :-1], lv[:, 1:]


def mc_targets(leaf_costs: torch.Tensor) -> list[torch.Tensor]:
    """Monte-Carlo targets of Alg. 1: ``c_{i,j}`` = sum of the leaf costs below pair
    ``(i, j)``. ``(B, 2**D)`` -> list over levels ``i = 0..D`` of ``(B, 2**i)``."""
    b, n = leaf_costs.shape
    depth = n.bit_length() - 1
    if 2**depth != n:
        raise ValueError(f"number of leaf costs must be a power of two, got {n}")
    return [leaf_costs.reshape(b, 2**i, 2 ** (depth - i)).sum(-1) for i in range(depth + 1)]


def td_lambda_targets(
    leaf_costs: torch.Tensor, values: list[torch.Tensor], lam: float
) -> list[torch.Tensor]:
    """TD(lambda) targets of eq. (8).

    ``leaf_costs``: ``(B, 2**D)`` = ``C(p_{D,j}, p_{D,j+1})``; ``values[i]``: ``(B, 2**i)``
    critic estimates ``V(p_{i,j}, p_{i,j+1})`` of the level-``i`` pairs (``values[0]`` is
    unused). Returns the targets ``c_i`` ``(B, 2**i)`` for ``i = 0..D``:
    ``c_D = leaf_costs`` and
    ``c_{i,j} = (1 - lam) (V(p_{i+1,2j}, p_{i+1,2j+1}) + V(p_{i+1,2j+1}, p_{i+1,2j+2}))
    + lam (c_{i+1,2j} + c_{i+1,2j+1})``
    (the children of pair ``(i, j)`` are the level-``i+1`` pairs ``2j`` and ``2j+1``).
    ``lam = 1`` gives `mc_targets`.
    """
    n = leaf_costs.shape[1]
    depth = n.bit_length() - 1
    if 2**depth != n or len(values) != depth + 1:
        raise ValueError("need 2**D leaf costs and D + 1 levels of values")
    out: list[torch.Tensor] = [leaf_costs]
    c = leaf_costs
    for i in range(depth - 1, -1, -1):
        v = values[i + 1]
        c = (1.0 - lam) * (v[:, 0::2] + v[:, 1::2]) + lam * (c[:, 0::2] + c[:, 1::2])
        out.append(c)
    return out[::-1]


def _depth_of(points: torch.Tensor) -> int:
    n = points.shape[1] - 1
    depth = n.bit_length() - 1
    if n < 1 or 2**depth != n:
        raise ValueError(f"trees need 2**D + 1 points, got {points.shape[1]}")
    return depth
