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
from pathlib import Path
from typing import Any

import numpy as np
import torch

import finsler
from learn.base import TrainResult
from learn.evaluation import EvalResult, evaluate_paths
from learn.loop import (
    RunLoop,
    best_record,
    eval_columns,
)
from learn.pg.config import PGConfig, cycle_depth, default_pg_config, schedule_total
from learn.pg.losses import c_tau, gaussian_entropy, gaussian_log_prob, pair_baseline, pg_loss
from learn.pg.policy import (
    build_policies,
    generate_pg_paths,
    load_pg_policy,
    sample_training_paths,
)
from learn.registry import Method, deprecated_entry, register_method

__all__ = ["PGTrainer", "train_pg"]


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
            self.policies = build_policies(cfg, self.metric).to(self.device)
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




register_method(Method(
    name="pg",
    summary="per-depth policies trained by policy gradient (eqs. 15, 16)",
    config_class=PGConfig,
    trainer=PGTrainer,
    load_policy=load_pg_policy,
    default_config=default_pg_config,
))
