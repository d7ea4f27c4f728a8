"""The paper's policy-gradient baseline "PG" (section 5.2, eqs. (15)-(16), appendix B.3).

Per-depth stochastic policies ``pi_1 .. pi_Dmax`` (`DepthPolicy`, MLPs 64-64 tanh on
``(s, g)``): ``pi_D`` predicts the midpoint of a depth-``D`` tree's endpoints, the lower
policies ``pi_{D-1} .. pi_1`` fill the halves with their means. Training goes in ascending
depth; while ``pi_D`` is trained (only its parameters change), each **cycle**

1. samples ``pairs_per_cycle`` (30) start-goal pairs uniformly on the domain and
   ``samples_per_pair`` (10) midpoints per pair from ``pi_D`` (projected into the domain),
   completes each path deterministically and evaluates its ``2**D`` segment costs C in
   float64 with the metric's lowered torch program (``30 * 10 * 2**D`` evaluations: the
   paper's count, appendix B.3);
2. scores each path by ``c_tau`` of eq. (15), the sum of the squared costs of its two halves
   (`c_tau`), and subtracts the baseline ``b(p_0, p_{2^D})`` of eq. (16), the mean of
   the pair's 10 samples (`pair_baseline`);
3. takes ``epochs`` (1) Adam steps (lr 5e-3) on the PPO-style clipped surrogate with an
   entropy bonus (`pg_loss`: clip 0.2, entropy coefficient 1).

``pi_1`` is trained for ``cycles_first`` (1000) cycles, every other ``pi_D`` for
``cycles_other`` (538; Panda: 1077 for every level), so the default budget is the paper's
total: 20,613,600 evaluations of C for Matsumoto, 82,591,200 for car-like, 20,032,200 for
Panda. A budget larger than the schedule keeps training ``pi_Dmax``; a smaller one stops
mid-schedule.

Beyond the paper's text, as in the authors' SGT-PG code (``scripts/SGT_PG`` of
omron-sinicx/midpoint_learning, read for reference): ``pi_D`` starts from ``pi_{D-1}``'s
weights (``init_from_lower``) and, when its level ends, ``pi_D`` is reset to its best
state of the level on the validation set (``restore_level_best``). Options reproduce two
more details of that code (both off by default, the paper's text is followed):
``objective="sum"`` (its labels are the plain path length, not eq. 15) and
``surrogate="sgt-pg-code"`` (its clipped ratio is the constant ``1 + clip``), and
``swap_augment`` (it also trains on every pair reversed with the same label).

Accounting: PG uses values of C only (model-free); every evaluation of C made during
training is in a collected path, so ``timesteps`` (all-inclusive) equals
``timesteps_paper``; ``timesteps_derivative`` is 0. Validation evaluations are not counted.

Logged ``success_rate`` / ``mean_length`` / ``mean_max_segment_cost`` are measured, as the
paper does, at the depth ``D`` of the policy being trained (``2**D`` segments); the
``*_task_depth`` columns measure the same policies at the task's depth ``Dmax`` so the
curves compare with the other methods. ``checkpoint_best`` is chosen on the task depth.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

import finsler
from finsler.errors import InputError
from learn.base import LoadedPolicy, TrainResult
from learn.evaluation import EvalResult, check_pairs, evaluate_paths
from learn.loop import (
    RunLoop,
    best_record,
    eval_columns,
    load_run,
    load_weights,
    resolve_device,
)
from learn.mlp import mlp
from learn.registry import Method, deprecated_entry, register_method
from learn.run_config import (
    RunConfig,
    check_choice,
    check_hidden,
    ensure_registered,
    training_settings,
)
from learn.tree import build_tree

__all__ = [
    "DepthPolicy",
    "PGConfig",
    "PGPolicy",
    "PGTrainer",
    "c_tau",
    "cycle_depth",
    "default_pg_config",
    "gaussian_entropy",
    "gaussian_log_prob",
    "generate_pg_paths",
    "load_pg_policy",
    "pair_baseline",
    "pg_loss",
    "sample_training_paths",
    "schedule_total",
    "train_pg",
]

_OBJECTIVES = ("halves-squared", "sum")
_SURROGATES = ("ppo", "sgt-pg-code")
_ACTIVATIONS = ("tanh", "relu")


# ----------------------------------------------------------------------------------------
# Configuration
# ----------------------------------------------------------------------------------------
@dataclass
class PGConfig(RunConfig):
    """Every setting of one PG training run (saved as ``config.json``): the run fields of
    `learn.run_config.RunConfig` (``timesteps``: the budget of evaluations of C,
    all-inclusive, here equal to the paper's count; None = the schedule's total,
    `schedule_total`, the paper's total for the environment; ``depth``: the number
    of policies D_max; ``eval_every``: cycles between evaluations, and every level's last
    cycle is evaluated too), then PG's own."""

    config_methods: ClassVar[tuple[str, ...]] = ("pg",)
    run_defaults: ClassVar[Mapping[str, Any]] = {"timesteps": None}

    hidden: tuple[int, ...] = (64, 64)
    """Hidden layer sizes of every policy (paper: 64, 64)."""
    activation: str = "tanh"
    """``tanh`` (paper) or ``relu``."""
    normalize_inputs: bool = False
    """Beyond the paper: scale (s, g) to [-1, 1] by the domain's bounds before the MLP."""
    base_std: float = 0.05
    """Base standard deviation: std_i = Softplus(sigma_i) + (base_std + Softplus(c_i)) |s - g|."""
    init_c: float = 0.0
    """Initial value of the learnable c_i of the standard deviation."""
    lr: float = 5e-3
    """Adam learning rate (paper: 5e-3)."""
    pairs_per_cycle: int = 30
    """Start-goal pairs sampled per cycle (paper: 30)."""
    samples_per_pair: int = 10
    """Midpoints sampled from pi_D per pair (paper: 10); at least 2 (the baseline is their
    mean)."""
    clip: float = 0.2
    """PPO clipping parameter (paper: 0.2)."""
    entropy_coef: float = 1.0
    """Entropy coefficient (paper: 1)."""
    epochs: int = 1
    """Full-batch gradient steps per cycle (paper: 1)."""
    cycles_first: int | None = None
    """Cycles of pi_1; None = 1000 (Panda: 1077)."""
    cycles_other: int | None = None
    """Cycles of each pi_D, D >= 2; None = 538 (Panda: 1077). pi_Dmax keeps training if the
    budget is larger than the schedule."""
    objective: str = "halves-squared"
    """``halves-squared``: c_tau of eq. (15); ``sum``: the path length (the labels of the
    authors' SGT-PG code and of the original SGT-PG)."""
    surrogate: str = "ppo"
    """``ppo``: max(r A, clip(r, 1-clip, 1+clip) A); ``sgt-pg-code``: max(r A, (1+clip) A),
    what the authors' code computes."""
    init_from_lower: bool = True
    """Start pi_D from pi_{D-1}'s weights (the authors' code: init_from_lower_level)."""
    restore_level_best: bool = True
    """When pi_D's level ends, reset pi_D to its best state of the level on the validation
    set at depth D (success, then lower mean max segment cost), as the authors' code restores
    its best model at the end of each level."""
    swap_augment: bool = False
    """Also train on every pair reversed (g, s) with the same midpoint and advantage (the
    authors' code does; questionable for non-reversible metrics)."""
    def complete(self) -> None:
        """The schedule's defaults for the environment, and its total as the budget."""
        first, other = training_settings(self.env).pg_cycles
        if self.cycles_first is None:
            self.cycles_first = first
        if self.cycles_other is None:
            self.cycles_other = other
        if self.timesteps is None:
            self.timesteps = schedule_total(self)

    def validate(self) -> None:
        """Raise `InputError` naming the first impossible field of PG's own (the run
        fields are [`RunConfig`][learn.RunConfig]'s to check)."""
        check_choice("activation", self.activation, _ACTIVATIONS)
        check_choice("objective", self.objective, _OBJECTIVES)
        check_choice("surrogate", self.surrogate, _SURROGATES)
        for name in ("pairs_per_cycle", "epochs", "cycles_first", "cycles_other"):
            v = getattr(self, name)
            if v is not None and v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if self.samples_per_pair < 2:
            raise InputError("samples_per_pair must be at least 2 (the baseline is the mean "
                             f"of the pair's samples), got {self.samples_per_pair!r}")
        check_hidden(self.hidden)
        _real("lr", self.lr, 0.0, 1.0)
        _real("clip", self.clip, 0.0, 1.0)
        _real("base_std", self.base_std, 0.0, math.inf)
        if not (0.0 <= self.entropy_coef < math.inf):
            raise InputError(f"entropy_coef must be finite and >= 0, got {self.entropy_coef!r}")
        if not math.isfinite(self.init_c):
            raise InputError(f"init_c must be finite, got {self.init_c!r}")

    # ------------------------------------------------------------------------------------
    @property
    def model_free(self) -> bool:
        """Always True: PG uses values of C only."""
        return True

    def cycle_evaluations(self, depth: int) -> int:
        """Evaluations of C in one cycle at ``depth``: pairs * samples * 2**depth."""
        return self.pairs_per_cycle * self.samples_per_pair * 2**depth


def _real(name: str, value: float, lo: float, hi: float) -> None:
    """``lo < value < hi`` (open interval; hi may be inf)."""
    if not (lo < value < hi):
        raise InputError(f"{name} must be in ({lo:g}, {hi:g}), got {value!r}")


def default_pg_config(env: str, **overrides: Any) -> PGConfig:
    """The paper's PG settings (appendix B.3) for ``env``; ``overrides`` replace fields."""
    ensure_registered(env, overrides.get("metric_class"))
    return PGConfig(env=env, **overrides)


def cycle_depth(cfg: PGConfig, cycle: int) -> int:
    """Depth D of the policy trained in the ``cycle``-th cycle (0-based): 1 for the first
    ``cycles_first`` cycles, then ``cycles_other`` cycles per depth, Dmax for ever after."""
    assert cfg.cycles_first is not None and cfg.cycles_other is not None
    if cycle < cfg.cycles_first:
        return 1
    return min(2 + (cycle - cfg.cycles_first) // cfg.cycles_other, cfg.max_depth)


def schedule_total(cfg: PGConfig) -> int:
    """Evaluations of C of the whole schedule (the paper's total, appendix B.3):
    ``P * K * (2 * cycles_first + sum_{D=2..Dmax} 2**D * cycles_other)``."""
    first, other = training_settings(cfg.env).pg_cycles
    cf = cfg.cycles_first if cfg.cycles_first is not None else first
    co = cfg.cycles_other if cfg.cycles_other is not None else other
    per = cfg.pairs_per_cycle * cfg.samples_per_pair
    return per * (2 * cf + sum(2**d * co for d in range(2, cfg.max_depth + 1)))


# ----------------------------------------------------------------------------------------
# Policies
# ----------------------------------------------------------------------------------------
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


def _build_policies(cfg: PGConfig, metric: finsler.Metric) -> nn.ModuleList:
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


# ----------------------------------------------------------------------------------------
# Objective and gradient estimator (eqs. 15, 16)
# ----------------------------------------------------------------------------------------
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
        raise InputError(f"surrogate must be one of {', '.join(_SURROGATES)}; got {surrogate!r}")
    surr = torch.maximum(ratio * advantage, clipped * advantage).mean()
    ent = entropy.mean()
    loss = surr - entropy_coef * ent
    parts = {
        "surrogate": float(surr.detach()),
        "entropy": float(ent.detach()),
        "clipped_fraction": float(((ratio - 1.0).abs() > clip).double().mean()),
    }
    return loss, parts


# ----------------------------------------------------------------------------------------
# Training
# ----------------------------------------------------------------------------------------
def _eval_key(ev: EvalResult) -> tuple[float, float]:
    """Selection key: success first, then lower mean max segment cost."""
    return (ev.success_rate, -ev.mean_max_segment_cost)


def _run_document(cfg: PGConfig) -> dict[str, Any]:
    """``config.json``'s sections about PG."""
    return {
        "objective": "c_tau of eq. (15)" if cfg.objective == "halves-squared"
        else "path length (sum of C)",
        "model_free": True,
        "uses_derivative_of_C": [],
        "schedule": {
            "cycles_per_depth": [cfg.cycles_first] + [cfg.cycles_other] * (cfg.max_depth - 1),
            "evaluations_per_cycle": [cfg.cycle_evaluations(d)
                                      for d in range(1, cfg.max_depth + 1)],
            "total": schedule_total(cfg),
        },
        "counts": "timesteps = every evaluation of C made in training (all-inclusive; all are "
                  "in collected paths, so it equals timesteps_paper = pairs * samples * 2**D "
                  "per cycle); timesteps_derivative = 0 (values of C only)",
        "columns": "success_rate, mean_length, mean_max_segment_cost: validation set at the "
                   "depth of the policy being trained (as the paper); *_task_depth: at the "
                   "task's depth",
        "selection": f"checkpoint_best by success_rate_task_depth on finsler.validation_pairs "
                     f"(seed {finsler.VALIDATION_SEED}, {cfg.eval_pairs} pairs), ties by "
                     "lower mean_max_segment_cost_task_depth",
    }


class PGTrainer(RunLoop):
    """Train the per-depth policies of a `PGConfig` into a run directory (the
    loop: [`learn.loop.RunLoop`][learn.loop.RunLoop]). One iteration is one cycle; a cycle is only
    started if it fits the budget; every level's last cycle is also evaluated."""

    config_class = PGConfig
    label = "pg"
    free_on_resume = ("minutes", "device", "timesteps")
    final_columns = ("success_rate_task_depth", "mean_length_task_depth",
                     "mean_max_segment_cost_task_depth")

    def setup(self) -> None:
        cfg = self.cfg
        self.eval_pairs = torch.as_tensor(self.validation_pairs, dtype=torch.float64,
                                          device=self.device)
        with self.seeded():
            self.policies = _build_policies(cfg, self.metric).to(self.device)
        self.opts = [torch.optim.Adam(p.parameters(), lr=cfg.lr) for p in self.policies]
        self.np_rng, self.gen = self.generators()

        self.level = 1  # depth of the policy being trained
        self.level_best: dict[str, Any] | None = None  # best state of pi_level on validation
        self._level_ends = False
        self._stats: list[dict[str, float]] = []

    def state_dict(self) -> dict[str, Any]:
        return {
            "policies": [p.state_dict() for p in self.policies],
            "optimizers": [o.state_dict() for o in self.opts],
            "np_rng": self.np_rng.bit_generator.state,
            "torch_rng": self.gen.get_state(),
            "counters": {"level": self.level},
            "level_best": self.level_best,
        }

    def load_state_dict(self, st: dict[str, Any]) -> None:
        for p, sd in zip(self.policies, st["policies"], strict=True):
            p.load_state_dict(sd)
        for o, sd in zip(self.opts, st["optimizers"], strict=True):
            o.load_state_dict(sd)
        self.np_rng.bit_generator.state = st["np_rng"]
        self.gen.set_state(st["torch_rng"])
        self.level = int(st["counters"]["level"])
        self.level_best = st["level_best"]

    def policy_state(self) -> dict[str, Any]:
        return {"policies": [p.state_dict() for p in self.policies]}

    def run_document(self) -> dict[str, Any]:
        return _run_document(self.cfg)

    # -- the algorithm --------------------------------------------------------------------
    def _enter_level(self, depth: int) -> None:
        """Level change ``depth - 1`` -> ``depth``: restore pi_{depth-1}'s best state of its
        level (``restore_level_best``) and start pi_depth from it (``init_from_lower``)."""
        below = self.policies[depth - 2]
        if self.cfg.restore_level_best and self.level_best is not None:
            below.load_state_dict(self.level_best["state"])
        if self.cfg.init_from_lower:
            self.policies[depth - 1].load_state_dict(below.state_dict())
        self.level = depth
        self.level_best = None

    def has_budget(self) -> bool:
        """The next cycle fits the budget (a cycle is never started past it)."""
        d = cycle_depth(self.cfg, self.iteration)
        return self.timesteps + self.cfg.cycle_evaluations(d) <= self.cfg.timesteps

    def iterate(self) -> None:
        d = cycle_depth(self.cfg, self.iteration)
        if d != self.level:
            self._enter_level(d)
        self._stats.append(self.cycle())
        self._level_ends = cycle_depth(self.cfg, self.iteration) != d

    def evaluation_due(self) -> bool:
        return self.iteration % self.cfg.eval_every == 0 or self._level_ends

    def cycle(self) -> dict[str, float]:
        """One training cycle of ``pi_D`` (D = `level`): collect, eq. (15) costs,
        eq. (16) baseline, ``epochs`` Adam steps on `pg_loss`. Adds the evaluations
        of C to the counters; returns statistics for the log."""
        cfg, d = self.cfg, self.level
        pi, opt = self.policies[d - 1], self.opts[d - 1]
        p, k = cfg.pairs_per_cycle, cfg.samples_per_pair
        ends = finsler.sample_pairs(self.metric, p, self.np_rng)
        ends_t = torch.as_tensor(ends, dtype=torch.float64, device=self.device)
        s, g = ends_t[:, 0], ends_t[:, 1]
        raw, paths = sample_training_paths(self.policies, self.metric, s, g, d, k, self.gen)
        with torch.no_grad():
            seg = self.metric.path_costs(paths)  # (P*K, 2**D) float64
            cost = (c_tau(seg) if cfg.objective == "halves-squared" else seg.sum(-1))
            cost = cost.reshape(p, k)
            adv = (cost - pair_baseline(cost)[:, None]).reshape(-1)
        n_eval = paths.shape[0] * seg.shape[1]
        self.timesteps += n_eval
        self.timesteps_paper += n_eval

        ss, gg = s.repeat_interleave(k, 0), g.repeat_interleave(k, 0)
        xx = raw.reshape(-1, self.dim)
        if cfg.swap_augment:
            ss, gg = torch.cat([ss, gg]), torch.cat([gg, ss])
            xx, adv = torch.cat([xx, xx]), torch.cat([adv, adv])
        with torch.no_grad():
            logp_old = gaussian_log_prob(xx, *pi.distribution(ss, gg))
        for _ in range(cfg.epochs):
            mean, std = pi.distribution(ss, gg)
            loss, parts = pg_loss(gaussian_log_prob(xx, mean, std), logp_old, adv,
                                  gaussian_entropy(std), cfg.clip, cfg.entropy_coef,
                                  cfg.surrogate)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
        self.iteration += 1
        return {"loss": float(loss.detach()), **parts, "mean_cost": float(cost.mean()),
                "mean_std": float(std.detach().mean())}

    # -- evaluation -----------------------------------------------------------------------
    def evaluate(self, depth: int | None = None, pairs: torch.Tensor | None = None) -> EvalResult:
        """Section 5.1 evaluation of the deterministic policies at ``depth`` (default Dmax)
        on ``pairs`` ``(K, 2, dim)`` (default: the validation set)."""
        pt = self.eval_pairs if pairs is None else pairs
        d = self.depth_max if depth is None else depth
        paths = generate_pg_paths(self.policies, self.metric, pt[:, 0], pt[:, 1], d)
        return evaluate_paths(self.metric, paths.cpu().numpy(), self.cfg.eval_eps)

    def evaluation(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """The policy being trained at its depth (the paper's curves) and all of them at
        the task's depth (the best checkpoint is chosen there); keeps the level's best."""
        d = self.level
        ev = self.evaluate(d)
        ev_task = ev if d == self.depth_max else self.evaluate(self.depth_max)
        stats = {k: float(np.mean([s[k] for s in self._stats])) if self._stats else math.nan
                 for k in ("loss", "surrogate", "entropy", "mean_cost", "mean_std")}
        self._stats = []
        # best state of the level's policy (restored when the level ends)
        key = _eval_key(ev)
        if self.level_best is None or key > tuple(self.level_best["key"]):
            self.level_best = {"key": list(key), "iteration": self.iteration,
                               "state": copy.deepcopy(self.policies[d - 1].state_dict())}
        columns = {"depth": d, **eval_columns(ev), **eval_columns(ev_task, "_task_depth"),
                   **stats}
        return columns, best_record(ev_task, timesteps=self.timesteps,
                                    iteration=self.iteration, depth=d)

    def rates(self, wall: float) -> dict[str, Any]:
        return {"cycles_per_second": round(self.iteration / max(wall, 1e-9), 3)}

    def progress_fields(self, row: dict[str, Any]) -> dict[str, Any]:
        return {"depth": row["depth"], "success": f"{row['success_rate']:.2f}",
                "task": f"{row['success_rate_task_depth']:.2f}"}


def train_pg(cfg: PGConfig, out: str | Path, resume: bool = False,
             progress: bool = True) -> TrainResult:
    """Deprecated: `learn.train_run` (the one entry point for every method) trains
    ``cfg`` the same way. Train PG with ``cfg`` into run directory ``out`` (``resume``
    continues the run saved there exactly as an uninterrupted run would; a non-empty
    ``out`` without ``resume`` is refused)."""
    deprecated_entry("learn.pg.train_pg")
    return PGTrainer(cfg, out, resume=resume, progress=progress).run()


# ----------------------------------------------------------------------------------------
# Loading and using a trained PG policy
# ----------------------------------------------------------------------------------------
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
    policies = _build_policies(cfg, cfg.metric)
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


register_method(Method(
    name="pg",
    summary="per-depth policies trained by policy gradient (eqs. 15, 16)",
    config_class=PGConfig,
    trainer=PGTrainer,
    load_policy=load_pg_policy,
    default_config=default_pg_config,
))
