"""PG's objective and gradient estimator: ``c_tau`` of eq. (15), the baseline of eq. (16),
the Gaussian log-density and entropy, and the clipped surrogate `pg_loss`."""

from __future__ import annotations

import math

import torch

from finsler.errors import InputError
from learn.pg.config import SURROGATES

__all__ = ["c_tau", "gaussian_entropy", "gaussian_log_prob", "pair_baseline", "pg_loss"]



def c_tau(segment_costs: torch.Tensor) -> torch.Tensor:
    """Eq. (15): ``(sum of the first half's costs)**2 + (sum of the second half's)**2``.
    ``(N, 2**D)`` -> ``(N,)``."""
    n = segment_costs.shape[-1]
    if n < 2 or n % 2:
        raise InputError(f"c_tau needs an even number (>= 2) of segment costs, got {n}")
    first = segment_costs[..., : n // 2].sum(-1)
    second = segment_costs[..., n // 2 :].sum(-1)
    return first**2 + second**2


def pair_baseline(costs: torch.Tensor) -> torch.Tensor:
    """Baseline ``b(p_0, p_{2^D})`` of eq. (16): the mean over a pair's samples.
    ``(P, K)`` -> ``(P,)``."""
    return costs.mean(-1)


def gaussian_log_prob(x: torch.Tensor, mean: torch.Tensor, std: torch.Tensor) -> torch.Tensor:
    """Log-density of the diagonal Gaussian: ``(N, dim)`` x3 -> ``(N,)``."""
    z = (x - mean) / std
    return (-0.5 * z**2 - torch.log(std) - 0.5 * math.log(2.0 * math.pi)).sum(-1)


def gaussian_entropy(std: torch.Tensor) -> torch.Tensor:
    """Entropy of the diagonal Gaussian ``sum_i log(std_i) + dim (1 + log 2 pi) / 2``:
    ``(N, dim)`` -> ``(N,)``."""
    dim = std.shape[-1]
    return torch.log(std).sum(-1) + 0.5 * dim * (1.0 + math.log(2.0 * math.pi))


def pg_loss(log_prob: torch.Tensor, log_prob_old: torch.Tensor, advantage: torch.Tensor,
            entropy: torch.Tensor, clip: float = 0.2, entropy_coef: float = 1.0,
            surrogate: str = "ppo") -> tuple[torch.Tensor, dict[str, float]]:
    """The PPO-style estimator of eq. (16) for a cost to MINIMISE, all inputs ``(N,)``:

    ``loss = mean(max(r A, r_clip A)) - entropy_coef * mean(entropy)``, with
    ``r = exp(log_prob - log_prob_old)``, ``A = c_tau - b`` (``advantage``) and
    ``r_clip = clip(r, 1 - clip, 1 + clip)`` (``surrogate="ppo"``) or the constant
    ``1 + clip`` (``"sgt-pg-code"``, what the authors' code computes). At ``r = 1`` the
    gradient is ``mean(A grad log pi) - entropy_coef grad mean(entropy)``, eq. (16).
    Returns the scalar loss and its parts (``surrogate``, ``entropy``, ``clipped_fraction``).
    """
    ratio = torch.exp(log_prob - log_prob_old)
    if surrogate == "ppo":
        clipped = ratio.clamp(1.0 - clip, 1.0 + clip)
    elif surrogate == "sgt-pg-code":
        clipped = torch.full_like(ratio, 1.0 + clip)
    else:
        raise InputError(f"surrogate must be one of {', '.join(SURROGATES)}; got {surrogate!r}")
    surr = torch.maximum(ratio * advantage, clipped * advantage).mean()
    ent = entropy.mean()
    loss = surr - entropy_coef * ent
    parts = {
        "surrogate": float(surr.detach()),
        "entropy": float(ent.detach()),
        "clipped_fraction": float(((ratio - 1.0).abs() > clip).double().mean()),
    }
    return loss, parts


