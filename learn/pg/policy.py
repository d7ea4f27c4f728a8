"""PG's per-depth policies (`DepthPolicy`): building them, completing paths with their
means, sampling training paths, and the loaded policy (`PGPolicy`, `load_pg_policy`)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

import finsler
from finsler.errors import InputError
from learn.base import LoadedPolicy
from learn.evaluation import EvalResult, check_pairs, evaluate_paths
from learn.loop import (
    load_run,
    load_weights,
    resolve_device,
)
from learn.mlp import mlp
from learn.pg.config import PGConfig
from learn.tree import build_tree

__all__ = [
    "DepthPolicy",
    "PGPolicy",
    "build_policies",
    "generate_pg_paths",
    "load_pg_policy",
    "sample_training_paths",
]


class DepthPolicy(nn.Module):
    """``pi_D`` of appendix B.3: ``(s, g)`` ``(N, dim)`` -> diagonal Gaussian over the
    midpoint, mean ``(s + g) / 2 + m`` and standard deviation
    ``Softplus(sigma_i) + (base_std + Softplus(c_i)) ||s - g||`` (Euclidean norm of the
    coordinate difference, as in the paper and the SGT-PG code), where ``(m, sigma)`` is the
    MLP's output ``(N, 2 dim)`` and ``c`` a learnable ``(dim,)`` parameter.

    The MLP runs in float32; mean and std are returned in the dtype of ``s`` (float64 for
    costs and log-probabilities).
    """

    def __init__(self, metric: finsler.Metric, hidden: tuple[int, ...] = (64, 64),
                 activation: str = "tanh", normalize_inputs: bool = False,
                 base_std: float = 0.05, init_c: float = 0.0) -> None:
        super().__init__()
        self.dim = metric.dim
        self.base_std = float(base_std)
        self.net = mlp(2 * self.dim, 2 * self.dim, hidden, activation)
        self.c = nn.Parameter(torch.full((self.dim,), float(init_c)))
        lo, hi = metric.domain.bounds()
        finite = np.isfinite(lo) & np.isfinite(hi) & bool(normalize_inputs)
        center = np.where(finite, 0.5 * (lo + hi), 0.0)
        span = np.where(finite, 0.5 * (hi - lo), 1.0)
        self.register_buffer("center", torch.as_tensor(center, dtype=torch.float64))
        self.register_buffer("span", torch.as_tensor(span, dtype=torch.float64))

    def distribution(self, s: torch.Tensor, g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Unprojected mean and std, both ``(N, dim)`` in the dtype of ``s``."""
        x = torch.cat([(s - self.center) / self.span, (g - self.center) / self.span], -1)
        out = self.net(x.to(self.c.dtype)).to(s.dtype)
        m, sigma = out[:, : self.dim], out[:, self.dim :]
        gap = torch.linalg.vector_norm(g - s, dim=-1, keepdim=True)
        std = F.softplus(sigma) + (self.base_std + F.softplus(self.c.to(s.dtype))) * gap
        return 0.5 * (s + g) + m, std


def build_policies(cfg: PGConfig, metric: finsler.Metric) -> nn.ModuleList:
    return nn.ModuleList(
        DepthPolicy(metric, hidden=cfg.hidden, activation=cfg.activation,
                    normalize_inputs=cfg.normalize_inputs, base_std=cfg.base_std,
                    init_c=cfg.init_c)
        for _ in range(cfg.max_depth)
    )


def _means_predictor(
    levels: Sequence[DepthPolicy], project: Callable[[torch.Tensor], torch.Tensor]
) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """A ``predict(s, g)`` for `learn.tree.build_tree` that uses ``levels[0]`` on its
    first call, ``levels[1]`` on the second, ... (build_tree calls it once per level, top
    down): projected means."""
    it = iter(levels)

    def predict(s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        mean, _ = next(it).distribution(s, g)
        return project(mean)

    return predict


def generate_pg_paths(policies: Sequence[DepthPolicy], metric: finsler.Metric,
                      starts: torch.Tensor, goals: torch.Tensor, depth: int) -> torch.Tensor:
    """Deterministic paths of depth ``depth``: ``pi_depth`` (``policies[depth - 1]``) gives
    the midpoint of (start, goal), ``pi_{depth-1} .. pi_1`` the lower levels, all by their
    projected means. ``(K, dim)`` x2 -> ``(K, 2**depth + 1, dim)`` float64."""
    if not 0 <= depth <= len(policies):
        raise InputError(f"depth must be in [0, {len(policies)}] (one policy per depth), "
                         f"got {depth}")
    levels = [policies[d - 1] for d in range(depth, 0, -1)]
    with torch.no_grad():
        return build_tree(starts.to(torch.float64), goals.to(torch.float64), depth,
                          _means_predictor(levels, metric.domain.project))


def sample_training_paths(
    policies: Sequence[DepthPolicy], metric: finsler.Metric, starts: torch.Tensor,
    goals: torch.Tensor, depth: int, samples: int, generator: torch.Generator | None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """The paths of one training cycle at ``depth`` (no gradient).

    ``starts``, ``goals`` ``(P, dim)`` float64 -> ``raw`` ``(P, samples, dim)``: the
    unprojected Gaussian samples of ``pi_depth`` (their log-probabilities enter eq. 16) and
    ``paths`` ``(P * samples, 2**depth + 1, dim)`` (pair-major): start, the lower policies'
    means, the projected sample at index ``2**(depth-1)``, ..., goal.
    """
    p, dim = starts.shape
    with torch.no_grad():
        mean, std = policies[depth - 1].distribution(starts, goals)
        noise = torch.randn((p, samples, dim), generator=generator, dtype=mean.dtype,
                            device=mean.device)
        raw = mean[:, None] + std[:, None] * noise
        mid = metric.domain.project(raw.reshape(-1, dim))
        s = starts.repeat_interleave(samples, 0)
        g = goals.repeat_interleave(samples, 0)
        levels = [policies[d - 1] for d in range(depth - 1, 0, -1)]
        halves = build_tree(torch.cat([s, mid]), torch.cat([mid, g]), depth - 1,
                            _means_predictor(levels, metric.domain.project))
        n = p * samples
        paths = torch.cat([halves[:n], halves[n:, 1:]], 1)
    return raw, paths




class PGPolicy(LoadedPolicy):
    """Trained per-depth policies (deterministic means) for one metric."""

    def __init__(self, policies: Sequence[DepthPolicy], config: PGConfig,
                 source: str = "", checkpoint: str = "") -> None:
        super().__init__(config, source, checkpoint)
        self.policies = nn.ModuleList(policies).eval()

    def _points(self, x: Any, name: str) -> torch.Tensor:
        xn = self.metric.domain.check(x, name)
        return torch.as_tensor(xn, dtype=torch.float64, device=self.policies[0].c.device)

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """Paths ``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)`` float64 with D = ``depth`` (default
        the task's depth): ``pi_D`` then ``pi_{D-1} .. pi_1``, by their means."""
        d = self.depth if depth is None else depth
        if (not isinstance(d, (int, np.integer)) or isinstance(d, bool)
                or not 0 <= d <= self.depth):
            raise InputError(f"depth must be an integer in [0, {self.depth}] (one policy per "
                             f"depth), got {depth!r}")
        s = self._points(starts, "starts")
        g = self._points(goals, "goals")
        if s.shape != g.shape:
            raise InputError(f"starts and goals differ in shape: {tuple(s.shape)} vs "
                             f"{tuple(g.shape)}")
        return generate_pg_paths(self.policies, self.metric, s, g, int(d)).cpu().numpy()

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        """``pi_1``'s predicted midpoints ``(K, dim)`` (projected means)."""
        out = self.generate(starts, goals, depth=1)[:, 1]  # checks the points first
        return out[0] if np.ndim(starts) == 1 else out

    def evaluate(self, pairs: Any = None, eps: float | None = None,
                 depth: int | None = None) -> EvalResult:
        """Section 5.1 evaluation on ``pairs`` ``(K, 2, dim)`` (default: the environment's
        default evaluation set, ``finsler.default_pairs``)."""
        p = finsler.default_pairs(self.metric) if pairs is None else check_pairs(
            self.metric, pairs)
        paths = self.generate(p[:, 0], p[:, 1], depth=depth)
        return evaluate_paths(self.metric, paths, self.eps if eps is None else eps)


def load_pg_policy(run_dir: str | Path, checkpoint: str = "best",
                   device: str = "cpu", env: str | None = None,
                   metric_params: dict[str, Any] | None = None) -> PGPolicy:
    """Load the PG policies of a run directory. ``checkpoint``: ``best`` (best success at
    the task's depth on the validation set; falls back to the latest) or ``latest``;
    ``env`` / ``metric_params``, if given, must be the run's
    (`learn.run_config.check_run_metric`)."""
    path, cfg, ckpt, loaded = load_run(run_dir, checkpoint, PGConfig, ("pg",), env,
                                       metric_params)
    policies = build_policies(cfg, cfg.metric)
    load_weights(_Stack(policies), ckpt.get("policies"), path)
    policies = policies.to(resolve_device(device))
    return PGPolicy(list(policies), cfg, source=str(path), checkpoint=loaded)


class _Stack:
    """The per-depth policies loaded from a list of state dicts (one per depth)."""

    def __init__(self, policies: nn.ModuleList) -> None:
        self.policies = policies

    def load_state_dict(self, states: Any) -> None:
        for p, sd in zip(self.policies, states, strict=True):
            p.load_state_dict(sd)


