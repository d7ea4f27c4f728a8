"""Algorithm 1 (actor-critic midpoint learning), vectorised, with run directories.

One iteration of `Trainer` reads like Algorithm 1:

1. **collect**: sample pairs uniformly, build whole midpoint trees with the stochastic
   actor (one batched actor call per level), leaf costs with the lowered torch ``cost``
   of the metric in float64;
2. **targets**: Monte-Carlo sums of leaf costs for every node (or TD(lambda), eq. 8);
3. **update**: ``epochs`` passes of minibatch steps, critic (eq. 5) then actor
   (eq. 6 / 17 / 18).

``timesteps`` count **every** evaluation of C the learner makes during training: the
collected trees (the paper's count, 2**D per tree of depth D, kept as ``timesteps_paper``)
and whatever the extra actor terms of `learn.midpoint.losses` evaluate (path energy, route
search); ``timesteps_derivative`` counts the evaluations whose derivative the learner
used. The ``timesteps`` budget binds the all-inclusive count.
Every ``eval_every`` iterations the deterministic policy is evaluated on the
**validation** pair set (``finsler.validation_pairs``, never the default evaluation set
that ``evaluate`` and ``report`` use), a metrics row is written, the best checkpoint is
chosen there and the latest checkpoint saved atomically; resuming from it replays the run
exactly (all RNG and optimiser states are in the checkpoint). The run directory, budget,
limits, signals, rows and checkpoints are [`learn.loop.RunLoop`][learn.loop.RunLoop]'s, as for every
method; this module registers the midpoint family (``midpoint``, ``inter``,
``two-to-one`` and their sweep variants) in `learn.registry`.
"""

from __future__ import annotations

import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from learn.base import TrainResult
from learn.evaluation import EvalResult, evaluate_paths
from learn.loop import RunLoop, best_record, eval_columns, read_config_section
from learn.midpoint.config import (
    METHODS,
    TrainConfig,
    default_config,
    model_free_overrides,
    paper_config,
    run_document,
)
from learn.midpoint.losses import actor_loss_of, actor_terms
from learn.midpoint.policy import build_actor, build_critic, generate_paths, load_midpoint_policy
from learn.registry import Method, Variant, deprecated_entry, register_method
from learn.storage import LATEST_FILE, load_checkpoint
from learn.tree import build_tree, level_pairs, mc_targets, td_lambda_targets

__all__ = ["Trainer", "actor_loss", "read_run_config", "train"]

_LOG = logging.getLogger(__name__)


def actor_loss(method: str, v_first: torch.Tensor, v_second: torch.Tensor) -> torch.Tensor:
    """Per-pair actor loss from ``V(s, m)`` and ``V(m, g)`` ``(N,)``: eq. (6) ``midpoint``,
    eq. (17) ``inter``, eq. (18) ``two-to-one`` (see `learn.midpoint.losses.ACTOR_LOSSES`)."""
    return actor_loss_of(method)(v_first, v_second)


def paper_depth(trees_before: int, total_timesteps: int, max_depth: int) -> int:
    """Depth of the c-th tree (appendix B.1): ``floor(c / c_d)`` capped at ``max_depth``,
    ``c_d = floor(T / (2**(max_depth + 1) - 1)) + 1``."""
    c_d = total_timesteps // (2 ** (max_depth + 1) - 1) + 1
    return min(trees_before // c_d, max_depth)


#: The polish settings (`learn.midpoint.config.TrainConfig`): free on resume until the polish
#: begins; after that only ``polish_steps`` (where it stops) may change.
_POLISH_FIELDS = ("polish_steps", "polish_lr", "polish_pairs", "polish_eval_every")


class Trainer(RunLoop):
    """Run Algorithm 1 for a `TrainConfig` into a run directory (the loop:
    [`learn.loop.RunLoop`][learn.loop.RunLoop])."""

    config_class = TrainConfig
    label = "train"
    free_on_resume = (*RunLoop.free_on_resume, *_POLISH_FIELDS)
    """A finished run may be resumed with polish settings (the polish starts after the
    budget, so it is the polish a new run with them would make); once the polish has
    begun only ``polish_steps`` may change (`check_resume`)."""
    recorded_on_resume = _POLISH_FIELDS
    """New polish settings are written into ``config.json`` when the resumed run starts."""

    def setup(self) -> None:
        cfg = self.cfg
        self.eval_pairs = self.validation_pairs
        self.loss = actor_loss_of(cfg.method, cfg.actor_loss_power)
        self.terms = actor_terms(cfg)

        # networks, initialised from the seed without touching the global RNG
        with self.seeded():
            self.actor = build_actor(cfg, self.metric).to(self.device)
            self.critic = build_critic(cfg, self.metric).to(self.device)
        adam = dict(fused=True) if cfg.fused_adam else {}
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr, **adam)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr, **adam)
        self.opt_polish = torch.optim.Adam(self.actor.parameters(), lr=cfg.polish_lr, **adam)
        self.np_rng, self.gen = self.generators()

        self.trees = 0
        self.updates = 0
        self.skipped_steps = 0
        self.lr = cfg.lr
        self.polished = 0
        self._losses: list[tuple[float, float]] = []

    # -- state ----------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        return {
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "opt_actor": self.opt_actor.state_dict(),
            "opt_critic": self.opt_critic.state_dict(),
            "opt_polish": self.opt_polish.state_dict(),
            "np_rng": self.np_rng.bit_generator.state,
            "torch_rng": self.gen.get_state(),
            "counters": {"trees": self.trees, "updates": self.updates,
                         "skipped_steps": self.skipped_steps, "polished": self.polished},
            "terms": {t.name: st for t in self.terms if (st := t.state()) is not None},
        }

    def load_state_dict(self, st: dict[str, Any]) -> None:
        self.actor.load_state_dict(st["actor"])
        self.critic.load_state_dict(st["critic"])
        self.opt_actor.load_state_dict(st["opt_actor"])
        self.opt_critic.load_state_dict(st["opt_critic"])
        self.np_rng.bit_generator.state = st["np_rng"]
        self.gen.set_state(st["torch_rng"])
        c = st["counters"]
        self.trees, self.updates = int(c["trees"]), int(c["updates"])
        self.skipped_steps = int(c.get("skipped_steps", 0))
        self.polished = int(c.get("polished", 0))  # checkpoints from before the polish: 0
        if "opt_polish" in st:
            self.opt_polish.load_state_dict(st["opt_polish"])
        for t in self.terms:  # extra actor terms with state (expert iteration's buffer)
            if t.name in st.get("terms", {}):
                t.load(st["terms"][t.name], self.device)

    def policy_state(self) -> dict[str, Any]:
        return {"actor": self.actor.state_dict(), "critic": self.critic.state_dict()}

    def run_document(self) -> dict[str, Any]:
        return run_document(self.cfg)

    def result_extra(self) -> dict[str, Any]:
        return {"skipped_steps": self.skipped_steps, "polish_steps": self.polished}

    # -- the algorithm --------------------------------------------------------------------
    def depth_for(self, trees_before: int) -> int:
        if self.cfg.depth_schedule == "full":
            return self.depth_max
        return paper_depth(trees_before, self.cfg.timesteps, self.depth_max)

    def _sample(self, s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        m = self.actor(s.float(), g.float(), generator=self.gen)
        return m.to(torch.float64)

    def collect(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor, int]:
        """COLLECTDATA of Alg. 1 for a batch of trees: returns starts, goals ``(N, dim)``
        float64, targets ``(N,)`` float64 and the timesteps spent."""
        depth = self.depth_for(self.trees)
        per_tree = 2 ** (depth + 1) - 1 + (2**depth + 1 if self.cfg.zero_pairs else 0)
        n_trees = max(1, math.ceil(self.cfg.collection_size / per_tree))
        ends = finsler.sample_pairs(self.metric, n_trees, self.np_rng)
        ends_t = torch.as_tensor(ends, dtype=torch.float64, device=self.device)
        with torch.no_grad():
            pts = build_tree(ends_t[:, 0], ends_t[:, 1], depth, self._sample)
            leaf = self.metric.path_costs(pts)
            pairs = [level_pairs(pts, i) for i in range(depth + 1)]
            if self.cfg.targets == "td" and depth > 0:
                values = [
                    self.critic(s.reshape(-1, self.dim).float(),
                                g.reshape(-1, self.dim).float()).double().reshape(n_trees, -1)
                    for s, g in pairs
                ]
                targets = td_lambda_targets(leaf, values, self.cfg.td_lambda)
            else:
                targets = mc_targets(leaf)
        starts = [s.reshape(-1, self.dim) for s, _ in pairs]
        goals = [g.reshape(-1, self.dim) for _, g in pairs]
        costs = [c.reshape(-1) for c in targets]
        if self.cfg.zero_pairs:
            flat = pts.reshape(-1, self.dim)
            starts.append(flat)
            goals.append(flat)
            costs.append(torch.zeros(flat.shape[0], dtype=torch.float64, device=self.device))
        self.trees += n_trees
        return torch.cat(starts), torch.cat(goals), torch.cat(costs), n_trees * 2**depth

    def update(self, s: torch.Tensor, g: torch.Tensor, c: torch.Tensor) -> tuple[float, float]:
        """``epochs`` passes of minibatch updates: critic (eq. 5), then actor (the method's
        loss, eq. 6 / 17 / 18, plus the extra terms of `learn.midpoint.losses`). Adds the
        terms' evaluations of C to the counters."""
        for term in self.terms:
            self.timesteps += term.prepare(self)
        # terms may add critic data of their own (expert iteration: searched sub-paths)
        extra = [d for d in (term.critic_data(self) for term in self.terms) if d is not None]
        if extra:
            s = torch.cat([s, *(d[0] for d in extra)])
            g = torch.cat([g, *(d[1] for d in extra)])
            c = torch.cat([c, *(d[2] for d in extra)])
        s32, g32 = s.float(), g.float()
        target = self.critic.to_raw(c, s, g).float()
        # the relative critic has no target at a zero pair (log 0 = -inf): it is exact there
        # (a NaN target still reaches the loss, and its step is skipped and counted)
        keep = ~torch.isneginf(target)
        keep = None if bool(keep.all()) else keep
        n = s.shape[0]
        mb = self.cfg.minibatch_size
        lc_sum = la_sum = 0.0
        steps = 0
        for _ in range(self.cfg.epochs):
            perm = torch.randperm(n, generator=self.gen, device=self.device)
            for k in range(0, n, mb):
                idx = perm[k : k + mb]
                bs, bg = s32[idx], g32[idx]
                # critic step, eq. (5)
                err = self.critic.raw(bs, bg) - target[idx]
                if keep is None:
                    lc = (err**2).mean()
                else:
                    has = keep[idx]
                    lc = (err.where(has, 0.0) ** 2).sum() / has.sum().clamp_min(1)
                self.opt_critic.zero_grad(set_to_none=True)
                lc.backward()
                self._step_if_finite(self.opt_critic, self.critic, "critic")
                # actor step: the method's loss with the critic held fixed, plus the terms
                self.critic.requires_grad_(False)
                la = self._actor_loss(bs, bg)
                for term in self.terms:
                    out = term.step(self)
                    self.timesteps += out.evaluations
                    self.timesteps_derivative += out.derivative
                    if out.loss is not None:
                        la = la + out.loss
                self.opt_actor.zero_grad(set_to_none=True)
                la.backward()
                self._step_if_finite(self.opt_actor, self.actor, "actor")
                self.critic.requires_grad_(True)
                lc_sum += float(lc.detach())
                la_sum += float(la.detach())
                steps += 1
        self.updates += steps
        return lc_sum / max(steps, 1), la_sum / max(steps, 1)

    def _actor_loss(self, s: torch.Tensor, g: torch.Tensor) -> torch.Tensor:
        """The method's loss at a sampled midpoint (critic held fixed). With several actor
        heads every head's sample gets the loss (each descends into its own basin), and
        the scores learn, by cross-entropy, the head whose sample the critic rates best.
        With ``actor_pairs`` that many fresh uniform pairs join the minibatch (no
        evaluation of C)."""
        if self.cfg.actor_pairs:
            k = self.cfg.actor_pairs
            ends = finsler.sample_pairs(self.metric, k, self.np_rng)
            e = torch.as_tensor(ends, dtype=s.dtype, device=s.device)
            s, g = torch.cat([s, e[:, 0]]), torch.cat([g, e[:, 1]])
        if self.actor.heads == 1:
            m = self.actor(s, g, generator=self.gen)
            return self.loss(self.critic(s, m), self.critic(m, g)).mean()
        mean, std, scores = self.actor.candidates(s, g)
        n, h, dim = mean.shape
        noise = torch.randn(mean.shape, generator=self.gen, device=mean.device,
                            dtype=mean.dtype)
        m = self.actor.domain.project((mean + std * noise).reshape(n * h, dim))
        s_rep = s.repeat_interleave(h, 0)
        g_rep = g.repeat_interleave(h, 0)
        per = self.loss(self.critic(s_rep, m), self.critic(m, g_rep)).reshape(n, h)
        best = per.detach().argmin(-1)
        choice = torch.nn.functional.cross_entropy(scores, best)
        share = self.cfg.actor_head_share
        weight = torch.full_like(per, share)
        weight.scatter_(1, best[:, None], 1.0)
        return (weight * per).sum(-1).mean() + self.cfg.actor_head_weight * choice

    def _step_if_finite(self, opt: torch.optim.Optimizer, net: torch.nn.Module,
                        what: str) -> None:
        """``opt.step()`` unless a gradient is NaN or inf: then the step is skipped (the
        parameters and the optimiser's moments stay finite), counted in
        ``skipped_steps`` (``result.json``) and logged. One non-finite gradient would
        otherwise turn every parameter into NaN for the rest of the run."""
        grads = [p.grad for p in net.parameters() if p.grad is not None]
        if grads and not bool(torch.stack([torch.isfinite(g).all() for g in grads]).all()):
            self.skipped_steps += 1
            _LOG.warning("%s: non-finite %s gradient at %d evaluations of C; step skipped "
                         "(%d so far)", self.run_dir, what, self.timesteps, self.skipped_steps)
            opt.zero_grad(set_to_none=True)
            return
        opt.step()

    def _set_lr(self) -> float:
        cfg = self.cfg
        p = min(1.0, self.timesteps / cfg.timesteps)
        f = cfg.lr_final_fraction
        if cfg.lr_schedule == "linear":
            scale = 1.0 - (1.0 - f) * p
        elif cfg.lr_schedule == "cosine":
            scale = f + (1.0 - f) * 0.5 * (1.0 + math.cos(math.pi * p))
        else:
            scale = 1.0
        lr = cfg.lr * scale
        for opt in (self.opt_actor, self.opt_critic):
            for group in opt.param_groups:
                group["lr"] = lr
        return lr

    # -- the polish after the budget (values of the critic only) ----------------------------
    def check_resume(self, saved: TrainConfig, resumed: TrainConfig) -> None:  # type: ignore[override]
        """Once the polish has begun, only ``polish_steps`` of its settings may change."""
        changed = [k for k in _POLISH_FIELDS if getattr(saved, k) != getattr(resumed, k)]
        fixed = [k for k in changed if k != "polish_steps"]
        latest = self.run_dir / LATEST_FILE
        if fixed and latest.is_file():
            polished = int(load_checkpoint(latest).get("counters", {}).get("polished", 0))
            if polished:
                raise InputError(
                    f"cannot resume with different {', '.join(fixed)}: the run's polish has "
                    f"begun ({polished} steps) with " + ", ".join(
                        f"{k}={getattr(saved, k)!r}" for k in fixed)
                    + "; only polish_steps may change now (nothing was changed)")

    def _polishing(self) -> bool:
        return self.timesteps >= self.cfg.timesteps

    def has_budget(self) -> bool:
        return self.timesteps < self.cfg.timesteps or self.polished < self.cfg.polish_steps

    def evaluation_due(self) -> bool:
        if self._polishing():  # the trained policy's row when the budget ends, then the
            # polish's (a finished run resumed with a polish has the same rows)
            return self.polished % self.cfg.polish_eval_every == 0
        return super().evaluation_due()

    def polish_step(self) -> float:
        """One actor step of the polish (``TrainConfig.polish_steps``): the method's actor
        loss at the deterministic midpoints of the sub-pairs of the policy's own
        deterministic trees between ``polish_pairs`` fresh pairs, the critic frozen. No
        evaluation of C. Returns the loss."""
        cfg = self.cfg
        k = cfg.polish_pairs
        ends = finsler.sample_pairs(self.metric, k, self.np_rng)
        e = torch.as_tensor(ends, dtype=torch.float64, device=self.device)
        self.actor.eval()
        pts = generate_paths(self.actor, self.metric, e[:, 0], e[:, 1], self.depth_max)
        self.actor.train()
        pairs = [level_pairs(pts, i) for i in range(self.depth_max)]
        s = torch.cat([a.reshape(-1, self.dim) for a, _ in pairs]).float()
        g = torch.cat([b.reshape(-1, self.dim) for _, b in pairs]).float()
        self.critic.requires_grad_(False)
        try:
            m = self.actor(s, g, deterministic=True)
            loss = self.loss(self.critic(s, m), self.critic(m, g)).mean()
            for group in self.opt_polish.param_groups:
                group["lr"] = cfg.polish_lr
            self.opt_polish.zero_grad(set_to_none=True)
            loss.backward()
            self._step_if_finite(self.opt_polish, self.actor, "actor (polish)")
        finally:
            self.critic.requires_grad_(True)
        self.polished += 1
        return float(loss.detach())

    # -- one iteration and its evaluation (the loop calls these) ----------------------------
    def begin(self) -> None:
        self.lr = self._set_lr()

    def iterate(self) -> None:
        """Collect a batch of trees (the paper's timesteps), then `update`; after
        the budget, one `polish_step`."""
        if self._polishing():
            self.lr = self.cfg.polish_lr
            self._losses.append((float("nan"), self.polish_step()))
            self.iteration += 1
            return
        self.lr = self._set_lr()
        s, g, c, ts = self.collect()
        self.timesteps += ts
        self.timesteps_paper += ts
        self._losses.append(self.update(s, g, c))
        self.iteration += 1

    def evaluate(self, pairs: np.ndarray | None = None) -> EvalResult:
        """Section 5.1 evaluation of the deterministic policy (default pair set)."""
        p = self.eval_pairs if pairs is None else pairs
        pt = torch.as_tensor(p, dtype=torch.float64, device=self.device)
        self.actor.eval()
        paths = generate_paths(self.actor, self.metric, pt[:, 0], pt[:, 1], self.depth_max)
        self.actor.train()
        return evaluate_paths(self.metric, paths.cpu().numpy(), self.cfg.eval_eps)

    def evaluation(self) -> tuple[dict[str, Any], dict[str, Any]]:
        ev = self.evaluate()
        lc, la = (np.mean(self._losses, axis=0) if self._losses else (float("nan"),) * 2)
        self._losses = []
        columns = {"depth": self.depth_for(self.trees), **eval_columns(ev),
                   "critic_loss": float(lc), "actor_loss": float(la), "lr": self.lr}
        more: dict[str, Any] = {"timesteps": self.timesteps}
        if self.cfg.select_eps is not None:  # TrainConfig.select_eps
            sel = float((ev.max_segment_cost <= self.cfg.select_eps).mean())
            columns["success_rate_select"] = sel
            more["selection_success"] = sel
        return columns, best_record(ev, **more)

    def progress_fields(self, row: dict[str, Any]) -> dict[str, Any]:
        return {"success": f"{row['success_rate']:.2f}",
                "C_s": f"{row['evaluations_per_second']:.0f}"}


def train(cfg: TrainConfig, out: str | Path, resume: bool = False,
          progress: bool = True) -> TrainResult:
    """Deprecated: `learn.train_run` (the one entry point for every method) trains
    ``cfg`` the same way. Train a midpoint policy with ``cfg`` into run directory ``out``
    (``resume`` continues the run saved there, replaying exactly what an uninterrupted
    run does)."""
    deprecated_entry("learn.train")
    return Trainer(cfg, out, resume=resume, progress=progress).run()


def read_run_config(run_dir: str | Path) -> TrainConfig:
    """The [`TrainConfig`][learn.TrainConfig] saved in a run directory."""
    return TrainConfig.from_dict(read_config_section(run_dir))


# -- the registry entry of the midpoint family ---------------------------------------------
def _model_free(method: str) -> Any:
    # eqs. (17) / (18) have no power: a default actor_loss_power (Panda's) is eq. (6)'s
    plain = {} if method == "midpoint" else {"actor_loss_power": 2.0}

    def make(env: str, **fields: Any) -> TrainConfig:
        return default_config(env, **{**model_free_overrides(env), "method": method,
                                      **plain, **fields})
    return make


register_method(Method(
    name="midpoint",
    summary="Algorithm 1: the midpoint-tree actor-critic, actor loss of eq. (6); inter: "
            "eq. (17), two-to-one: eq. (18)",
    config_class=TrainConfig,
    trainer=Trainer,
    load_policy=load_midpoint_policy,
    default_config=default_config,
    config_methods=METHODS,
    variants={
        "midpoint": Variant("the toolkit's defaults (may differentiate C: see config.json "
                            "model_free)", default_config),
        "midpoint-free": Variant("the model-free defaults: every term that differentiates C "
                                 "off (values only), with the passes per collection "
                                 "measured best without them", _model_free("midpoint")),
        "paper": Variant("appendix B.1's settings (values of C only)", paper_config),
        "inter": Variant("midpoint-free with the actor loss of eq. (17)", _model_free("inter")),
        "two-to-one": Variant("midpoint-free with the actor loss of eq. (18)",
                              _model_free("two-to-one")),
    },
    presets={"paper": "paper", "model-free": "midpoint-free"},
))
