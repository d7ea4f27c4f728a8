"""Actor and critic networks of the midpoint actor-critic (section 4.2, appendix B.1).

* `Actor`: MLP on ``(s, g)`` -> diagonal Gaussian (mean, log-std) over coordinates,
  reparametrised sampling, output projected into the domain with the domain's
  differentiable torch projection. Evaluation uses the mean.
* `Critic`: MLP on ``(s, g)`` -> distance estimate ``V(s, g)``, optionally through a
  target transform (``log1p``: the network regresses ``log(1 + c)``).
* `predictor`: the actor as ``predict(s, g)`` -> float64 projected midpoints, the one
  form generation, the route search, warm starts and the expert term call it in.

Networks work in float32; callers cast to float64 for costs and success checks.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import torch
from torch import nn

import finsler
from finsler.errors import InputError
from learn.mlp import mlp

__all__ = ["PREDICT_ROWS", "Actor", "Critic", "predictor"]


class _Scaler(nn.Module):
    """Affine map of coordinates to [-1, 1] by the domain's bounds (identity if disabled)."""

    def __init__(self, domain: finsler.Domain, enabled: bool) -> None:
        super().__init__()
        lo, hi = domain.bounds()
        finite = np.isfinite(lo) & np.isfinite(hi) & enabled
        center = np.where(finite, 0.5 * (lo + hi), 0.0)
        half = np.where(finite, 0.5 * (hi - lo), 1.0)
        self.register_buffer("center", torch.as_tensor(center, dtype=torch.float32))
        self.register_buffer("span", torch.as_tensor(half, dtype=torch.float32))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return (x - self.center) / self.span


class Actor(nn.Module):
    """Midpoint predictor ``pi(s, g)``: ``(N, dim), (N, dim)`` -> Gaussian over ``(N, dim)``.

    With ``residual`` the mean is ``(s + g) / 2 + half_range * out`` (the network predicts a
    correction to the coordinate midpoint); otherwise the mean is the raw output, mapped
    back from normalised coordinates. With ``relative`` (implies a residual mean) the
    network sees the pair as centre, unit direction and length ``r`` of ``g - s`` in
    normalised coordinates, and its offset and standard deviation are multiples of
    ``r``: a sub-pair deep in the tree gets the same relative precision as the top pair
    (with an absolute offset its correction is a few hundredths of the output's scale).
    With ``explore_std > 0`` the standard deviation is at least ``explore_std * |g - s|``
    (the learned one otherwise collapses to its clamp and exploration stops). With
    ``heads > 1`` the network gives that many Gaussians and a score each
    (`candidates`); the policy is the best-scored head's. Samples and means are
    projected into the domain.
    """

    def __init__(
        self,
        metric: finsler.Metric,
        hidden: tuple[int, ...] = (64, 64),
        activation: str = "relu",
        normalize_inputs: bool = False,
        residual: bool = False,
        relative: bool = False,
        log_std_min: float = -20.0,
        log_std_max: float = 2.0,
        init_log_std: float | None = None,
        explore_std: float = 0.0,
        heads: int = 1,
    ) -> None:
        super().__init__()
        self.heads = int(heads)
        self.domain = metric.domain
        self.explore_std = float(explore_std)
        self.dim = metric.dim
        self.residual = residual or relative
        self.relative = relative
        self.log_std_min = float(log_std_min)
        self.log_std_max = float(log_std_max)
        self.scaler = _Scaler(metric.domain, normalize_inputs)
        n_in = 2 * self.dim + 1 if relative else 2 * self.dim
        # per head: dim means then dim log-stds; then one score per head (heads > 1)
        n_out = self.heads * 2 * self.dim + (self.heads if self.heads > 1 else 0)
        self.net = mlp(n_in, n_out, hidden, activation)
        last = self.net[-1]
        with torch.no_grad():
            if init_log_std is not None:
                for k in range(self.heads):
                    rows = slice((2 * k + 1) * self.dim, (2 * k + 2) * self.dim)
                    last.weight[rows] *= 0.01
                    last.bias[rows] = float(init_log_std)
            # distinct starts: head k >= 1 begins offset along +-axis (k - 1) // 2 by a
            # quarter of the output scale, so the candidates descend into different basins
            for k in range(1, self.heads):
                axis, sign = ((k - 1) // 2) % self.dim, 1.0 if k % 2 else -1.0
                last.bias[2 * k * self.dim + axis] += 0.25 * sign

    def candidates(self, s: torch.Tensor, g: torch.Tensor
                   ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor | None]:
        """Every head's unprojected Gaussian: means ``(N, H, dim)``, standard deviations
        ``(N, H, dim)`` and scores ``(N, H)`` (None for one head)."""
        half = self.scaler.span
        if self.relative:
            d = (g - s) / half
            # smooth at d = 0 (the gradient of |d| is not): 1e-6 is far below any pair's
            # length in normalised coordinates, and a zero pair keeps mean = s, std = 0
            r = torch.sqrt((d * d).sum(-1, keepdim=True) + 1e-12)
            out = self.net(torch.cat([self.scaler(0.5 * (s + g)), d / r, r], -1))
            half = half * r
        else:
            out = self.net(torch.cat([self.scaler(s), self.scaler(g)], -1))
        n, h, dim = out.shape[0], self.heads, self.dim
        gauss = out[:, : 2 * h * dim].reshape(n, h, 2 * dim)
        scores = out[:, 2 * h * dim :] if h > 1 else None
        mu, log_std = gauss[..., :dim], gauss[..., dim:]
        log_std = log_std.clamp(self.log_std_min, self.log_std_max)
        half = half.unsqueeze(-2)  # (N, 1, dim) or (1, dim): the same scale for every head
        base = 0.5 * (s + g).unsqueeze(1) if self.residual else self.scaler.center
        mean = base + half * mu
        std = half * log_std.exp()
        if self.explore_std > 0:
            # exploration floor proportional to the pair's coordinate distance, so every
            # level of the tree keeps exploring at its own scale
            gap = (g - s).norm(dim=-1, keepdim=True).unsqueeze(1)
            std = torch.maximum(std, self.explore_std * gap)
        return mean, std, scores

    def distribution(self, s: torch.Tensor, g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Unprojected Gaussian mean ``(N, dim)`` and standard deviation ``(N, dim)`` (of
        the best-scored head when there are several)."""
        mean, std, scores = self.candidates(s, g)
        if scores is None:
            return mean[:, 0], std[:, 0]
        pick = scores.argmax(-1)
        rows = torch.arange(mean.shape[0], device=mean.device)
        return mean[rows, pick], std[rows, pick]

    def forward(
        self, s: torch.Tensor, g: torch.Tensor, generator: torch.Generator | None = None,
        deterministic: bool = False,
    ) -> torch.Tensor:
        """A reparametrised sample (or the mean if ``deterministic``), projected into the
        domain: ``(N, dim)``."""
        mean, std = self.distribution(s, g)
        if deterministic:
            x = mean
        else:
            noise = torch.randn(mean.shape, generator=generator, device=mean.device,
                                dtype=mean.dtype)
            x = mean + std * noise
        return self.domain.project(x)


class Critic(nn.Module):
    """Distance estimate ``V(s, g)``: ``(N, dim), (N, dim)`` -> ``(N,)``.

    `raw` returns the network output on the regression scale (``log(1 + c)`` for the
    ``log1p`` transform); `forward` returns the distance estimate. With
    ``symmetric`` the output is ``(net(s, g) + net(g, s)) / 2`` (reversible metrics).

    The ``relative`` transform (beyond the paper) is the critic's counterpart of the
    relative actor: the network sees the pair as centre, unit direction and length ``r``
    of ``g - s`` in normalised coordinates and predicts ``log(c / r)``, so
    ``V = r * exp(net)``: the log of the path's mean speed, a bounded function, learned at
    the same relative precision for a sub-pair deep in the tree as for the top pair (with
    ``log1p`` a short pair's absolute error is a large fraction of its cost), and
    ``V(p, p) = 0`` by construction (zero pairs carry no regression target).
    """

    def __init__(
        self,
        metric: finsler.Metric,
        hidden: tuple[int, ...] = (64, 64),
        activation: str = "relu",
        normalize_inputs: bool = False,
        transform: str = "none",
        symmetric: bool = False,
    ) -> None:
        super().__init__()
        if transform not in ("none", "log1p", "relative"):
            raise finsler.InputError(f"unknown critic transform {transform!r}")
        self.transform = transform
        self.symmetric = symmetric
        self.scaler = _Scaler(metric.domain, normalize_inputs)
        n_in = 2 * metric.dim + 1 if transform == "relative" else 2 * metric.dim
        self.net = mlp(n_in, 1, hidden, activation)

    def _length(self, s: torch.Tensor, g: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Normalised coordinate difference ``(N, dim)`` and its length ``(N, 1)`` (smooth
        at 0, as the relative actor's)."""
        d = (g - s) / self.scaler.span
        return d, torch.sqrt((d * d).sum(-1, keepdim=True) + 1e-12)

    def raw(self, s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        if self.transform == "relative":
            d, r = self._length(s, g)
            c = self.scaler(0.5 * (s + g))
            out = self.net(torch.cat([c, d / r, r], -1))[:, 0]
            if self.symmetric:
                out = 0.5 * (out + self.net(torch.cat([c, -d / r, r], -1))[:, 0])
            return out
        a, b = self.scaler(s), self.scaler(g)
        out = self.net(torch.cat([a, b], -1))[:, 0]
        if self.symmetric:
            out = 0.5 * (out + self.net(torch.cat([b, a], -1))[:, 0])
        return out

    def to_raw(self, c: torch.Tensor, s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """Map distances ``c`` between ``s`` and ``g`` (targets) to the regression scale
        (``-inf`` for a zero cost under ``relative``: no target there)."""
        if self.transform == "relative":
            return torch.log(c) - torch.log(self._length(s, g)[1][:, 0].to(c.dtype))
        return torch.log1p(c) if self.transform == "log1p" else c

    def forward(self, s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        z = self.raw(s, g)
        if self.transform == "relative":
            return self._length(s, g)[1][:, 0] * torch.exp(z)
        return torch.expm1(z) if self.transform == "log1p" else z


#: Rows per actor call in `predictor` on a CPU. One call for 1e5 pairs allocates
#: each layer's activations (1e5 x width floats, tens of MB) afresh, which the allocator
#: maps page by page (about half of such a call's CPU time is system time) and which do
#: not stay in cache; calls of 4096 rows were 2.6x faster for the 128-128-128 Matsumoto
#: actor and car-like's 128-128, 1.8x for Panda's 256-256-256 (``benchmarks/
#: predict_rows.py``, quiet, CPU time incl. system, one thread), with the same midpoints
#: bit for bit (each row's product does not depend on the others). The route search and
#: the warm starts make 1e4-1e6 predictions per call; a plain tree of a few pairs is one
#: call as before.
PREDICT_ROWS = 4096


def predictor(actor: Actor, metric: finsler.Metric, rows: int | None = PREDICT_ROWS
              ) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    """``(s, g) -> m``: the actor's deterministic mean (float32 network), cast to float64
    and projected into the domain (call under ``torch.no_grad()``). On a CPU, batches
    larger than ``rows`` go through the actor in pieces of that size (None: one call, as
    on other devices, where one call is the fast one)."""
    if rows is not None and (isinstance(rows, bool) or not isinstance(rows, int) or rows < 1):
        raise InputError(f"rows must be a positive integer or None, got {rows!r}")
    param = next(actor.parameters())
    if param.device.type != "cpu":
        rows = None

    def predict(s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        sp, gp = s.to(param), g.to(param)
        if rows is None or len(sp) <= rows:
            m = actor(sp, gp, deterministic=True)
        else:
            m = torch.cat([actor(sp[i:i + rows], gp[i:i + rows], deterministic=True)
                           for i in range(0, len(sp), rows)])
        return metric.domain.project(m.to(torch.float64)).to(s.device)

    return predict
