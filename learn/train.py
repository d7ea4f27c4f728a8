"""Algorithm 1 (actor-critic midpoint learning), vectorised, with run directories.

One iteration of :class:`Trainer` reads like Algorithm 1:

1. **collect**: sample pairs uniformly, build whole midpoint trees with the stochastic
   actor (one batched actor call per level), leaf costs with the lowered torch ``cost``
   of the metric in float64;
2. **targets**: Monte-Carlo sums of leaf costs for every node (or TD(lambda), eq. 8);
3. **update**: ``epochs`` passes of minibatch steps, critic (eq. 5) then actor
   (eq. 6 / 17 / 18).

``timesteps`` count **every** evaluation of C the learner makes during training: the
collected trees (the paper's count, 2**D per tree of depth D, kept as ``timesteps_paper``)
and whatever the extra actor terms of :mod:`learn.methods` evaluate (path energy, route
search); ``timesteps_derivative`` counts the evaluations whose derivative the learner
used. The ``timesteps`` budget binds the all-inclusive count.
Every ``eval_every`` iterations the deterministic policy is evaluated on the
**validation** pair set (``finsler.validation_pairs``, never the default evaluation set
that ``evaluate`` and ``report`` use), a metrics row is written, the best checkpoint is
chosen there and the latest checkpoint saved atomically; resuming from it replays the run
exactly (all RNG and optimiser states are in the checkpoint).
"""

from __future__ import annotations

import logging
import math
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from learn.base import StopOnSignal, TrainResult, finish_run
from learn.config import TrainConfig, config_json
from learn.methods import actor_loss_of, actor_terms
from learn.networks import Critic, resolve_device
from learn.policy import EvalResult, build_actor, evaluate_paths, generate_paths
from learn.storage import (
    BEST_FILE,
    CONFIG_FILE,
    LATEST_FILE,
    METRICS_FILE,
    RESULT_FILE,
    CorruptFileError,
    atomic_write_text,
    check_run_dir,
    load_checkpoint,
    read_json,
    restore_history,
    save_checkpoint,
    write_metrics,
)
from learn.tree import build_tree, level_pairs, mc_targets, td_lambda_targets

__all__ = ["TrainResult", "Trainer", "actor_loss", "resolve_device", "train"]

_LOG = logging.getLogger(__name__)


def actor_loss(method: str, v_first: torch.Tensor, v_second: torch.Tensor) -> torch.Tensor:
    """Per-pair actor loss from ``V(s, m)`` and ``V(m, g)`` ``(N,)``: eq. (6) ``midpoint``,
    eq. (17) ``inter``, eq. (18) ``two-to-one`` (see :data:`learn.methods.ACTOR_LOSSES`)."""
    return actor_loss_of(method)(v_first, v_second)


def paper_depth(trees_before: int, total_timesteps: int, max_depth: int) -> int:
    """Depth of the c-th tree (appendix B.1): ``floor(c / c_d)`` capped at ``max_depth``,
    ``c_d = floor(T / (2**(max_depth + 1) - 1)) + 1``."""
    c_d = total_timesteps // (2 ** (max_depth + 1) - 1) + 1
    return min(trees_before // c_d, max_depth)


class Trainer:
    """Run Algorithm 1 for a :class:`TrainConfig` into a run directory."""

    def __init__(self, cfg: TrainConfig, run_dir: str | Path, resume: bool = False,
                 progress: bool = True) -> None:
        self.run_dir = check_run_dir(Path(run_dir), resume)
        self.progress = progress
        if resume:
            cfg = self._resume_config(cfg)
        self.cfg = cfg
        self.device = resolve_device(cfg.device)
        torch.set_num_threads(cfg.threads)
        self.metric = cfg.metric
        self.dim = self.metric.dim
        self.depth_max = cfg.max_depth
        self.eval_pairs = finsler.validation_pairs(self.metric, cfg.eval_pairs)
        self.loss = actor_loss_of(cfg.method)
        self.terms = actor_terms(cfg)

        # networks, initialised from the seed without touching the global RNG
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(cfg.seed)
            self.actor = build_actor(cfg, self.metric).to(self.device)
            self.critic = Critic(
                self.metric, hidden=cfg.hidden, activation=cfg.activation,
                normalize_inputs=cfg.normalize_inputs, transform=cfg.critic_transform,
                symmetric=cfg.symmetric_critic,
            ).to(self.device)
        adam = dict(fused=True) if cfg.fused_adam else {}
        self.opt_actor = torch.optim.Adam(self.actor.parameters(), lr=cfg.lr, **adam)
        self.opt_critic = torch.optim.Adam(self.critic.parameters(), lr=cfg.lr, **adam)
        self.np_rng = np.random.default_rng(cfg.seed)
        self.gen = torch.Generator(device=self.device)
        self.gen.manual_seed(cfg.seed + 1)

        self.iteration = 0
        self.timesteps = 0  # all-inclusive evaluations of C
        self.timesteps_paper = 0  # evaluations of C in collected trees (the paper's count)
        self.timesteps_derivative = 0  # evaluations of C that were differentiated
        self.trees = 0
        self.updates = 0
        self.skipped_steps = 0
        self.wall_before = 0.0
        self.best: dict[str, float] = {"success_rate": -1.0, "mean_max_segment_cost": math.inf}
        self.history: list[dict[str, Any]] = []
        self._losses: list[tuple[float, float]] = []
        if resume:
            if not (self.run_dir / LATEST_FILE).is_file():
                raise InputError(
                    f"cannot resume: {self.run_dir / LATEST_FILE} is missing (the run's "
                    "progress cannot be restored; nothing was changed). Start a new run "
                    "with another --out")
            self._load_state(load_checkpoint(self.run_dir / LATEST_FILE))
        else:
            self.run_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.run_dir / CONFIG_FILE, config_json(cfg))

    # -- resume ---------------------------------------------------------------------------
    def _resume_config(self, cfg: TrainConfig) -> TrainConfig:
        doc = read_json(self.run_dir / CONFIG_FILE)
        if "config" not in doc:
            raise CorruptFileError(f"{self.run_dir / CONFIG_FILE} has no 'config' section")
        saved = TrainConfig.from_dict(doc["config"])
        # Only run-control fields may change on resume; everything else defines the run.
        free = {"minutes", "device", "eval_pairs"}
        new, old = cfg.to_dict(), saved.to_dict()
        changed = [k for k in old if k not in free and new[k] != old[k]]
        if cfg.env != saved.env:
            raise InputError(f"cannot resume: run {self.run_dir} trains {saved.env!r}, "
                             f"not {cfg.env!r}")
        if changed:
            raise InputError("cannot resume with different settings: " + ", ".join(
                f"{k} ({old[k]!r} in the run, {new[k]!r} given)" for k in changed))
        return saved.replace(minutes=cfg.minutes, device=cfg.device)

    def _state(self) -> dict[str, Any]:
        return {
            "format": "learn-checkpoint-v1",
            "config": self.cfg.to_dict(),
            "actor": self.actor.state_dict(),
            "critic": self.critic.state_dict(),
            "opt_actor": self.opt_actor.state_dict(),
            "opt_critic": self.opt_critic.state_dict(),
            "np_rng": self.np_rng.bit_generator.state,
            "torch_rng": self.gen.get_state(),
            "counters": {
                "iteration": self.iteration,
                "timesteps": self.timesteps,
                "timesteps_paper": self.timesteps_paper,
                "timesteps_derivative": self.timesteps_derivative,
                "trees": self.trees,
                "updates": self.updates,
                "skipped_steps": self.skipped_steps,
                "wall_seconds": self._wall(),
            },
            "best": dict(self.best),
            "history": [dict(r) for r in self.history],
            "terms": {t.name: st for t in self.terms if (st := t.state()) is not None},
        }

    def _load_state(self, st: dict[str, Any]) -> None:
        try:
            self.actor.load_state_dict(st["actor"])
            self.critic.load_state_dict(st["critic"])
            self.opt_actor.load_state_dict(st["opt_actor"])
            self.opt_critic.load_state_dict(st["opt_critic"])
            self.np_rng.bit_generator.state = st["np_rng"]
            self.gen.set_state(st["torch_rng"])
            c = st["counters"]
            self.iteration, self.timesteps = int(c["iteration"]), int(c["timesteps"])
            self.timesteps_paper = int(c["timesteps_paper"])
            self.timesteps_derivative = int(c["timesteps_derivative"])
            self.trees, self.updates = int(c["trees"]), int(c["updates"])
            self.skipped_steps = int(c.get("skipped_steps", 0))
            self.wall_before = float(c["wall_seconds"])
            self.best = dict(st["best"])
            for t in self.terms:
                if t.name in st.get("terms", {}):
                    t.load(st["terms"][t.name], self.device)
        except (KeyError, RuntimeError, TypeError, ValueError) as err:
            raise CorruptFileError(
                f"checkpoint {self.run_dir / LATEST_FILE} does not match the run: {err}"
            ) from err
        self.history = restore_history(self.run_dir, st, self.iteration)

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
        ends = self.metric.domain.sample(2 * n_trees, self.np_rng).reshape(n_trees, 2, self.dim)
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
        loss, eq. 6 / 17 / 18, plus the extra terms of :mod:`learn.methods`). Adds the
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
        target = self.critic.to_raw(c).float()
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
                lc = ((self.critic.raw(bs, bg) - target[idx]) ** 2).mean()
                self.opt_critic.zero_grad(set_to_none=True)
                lc.backward()
                self._step_if_finite(self.opt_critic, self.critic, "critic")
                # actor step: the method's loss with the critic held fixed, plus the terms
                self.critic.requires_grad_(False)
                m = self.actor(bs, bg, generator=self.gen)
                la = self.loss(self.critic(bs, m), self.critic(m, bg)).mean()
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

    # -- evaluation, logging, checkpoints -------------------------------------------------
    def evaluate(self, pairs: np.ndarray | None = None) -> EvalResult:
        """Section 5.1 evaluation of the deterministic policy (default pair set)."""
        p = self.eval_pairs if pairs is None else pairs
        pt = torch.as_tensor(p, dtype=torch.float64, device=self.device)
        self.actor.eval()
        paths = generate_paths(self.actor, self.metric, pt[:, 0], pt[:, 1], self.depth_max)
        self.actor.train()
        return evaluate_paths(self.metric, paths.cpu().numpy(), self.cfg.eval_eps)

    def _wall(self) -> float:
        return self.wall_before + (time.perf_counter() - self._t0)

    def _log_and_checkpoint(self, lr: float) -> dict[str, Any]:
        ev = self.evaluate()
        wall = self._wall()
        lc, la = (np.mean(self._losses, axis=0) if self._losses else (float("nan"),) * 2)
        self._losses = []
        row = {
            "iteration": self.iteration,
            "timesteps": self.timesteps,
            "timesteps_paper": self.timesteps_paper,
            "timesteps_derivative": self.timesteps_derivative,
            "wall_seconds": round(wall, 3),
            "depth": self.depth_for(self.trees),
            "success_rate": ev.success_rate,
            "mean_length": round(ev.mean_length, 8),
            "mean_max_segment_cost": round(ev.mean_max_segment_cost, 8),
            "critic_loss": float(lc),
            "actor_loss": float(la),
            "lr": lr,
            "evaluations_per_second": round(self.timesteps / max(wall, 1e-9), 1),
        }
        self.history.append(row)
        write_metrics(self.run_dir / METRICS_FILE, self.history)
        key = (ev.success_rate, -ev.mean_max_segment_cost)
        if key > (self.best["success_rate"], -self.best["mean_max_segment_cost"]):
            self.best = {
                "success_rate": ev.success_rate,
                "mean_max_segment_cost": ev.mean_max_segment_cost,
                "mean_length": ev.mean_length,
                "timesteps": self.timesteps,
                "wall_seconds": wall,
            }
            save_checkpoint(self.run_dir / BEST_FILE, {
                "format": "learn-checkpoint-v1",
                "config": self.cfg.to_dict(),
                "actor": self.actor.state_dict(),
                "critic": self.critic.state_dict(),
                "eval": dict(self.best),
            })
        save_checkpoint(self.run_dir / LATEST_FILE, self._state())
        return row

    def run(self) -> TrainResult:
        """Train until ``timesteps`` (or ``minutes``) are spent; returns the summary."""
        from tqdm.auto import tqdm

        cfg = self.cfg
        self._t0 = time.perf_counter()
        (self.run_dir / RESULT_FILE).unlink(missing_ok=True)  # finished again at the end
        bar = tqdm(total=cfg.timesteps, initial=self.timesteps, unit="C", unit_scale=True,
                   disable=not self.progress, desc=f"train {cfg.env}", dynamic_ncols=True)
        lr = self._set_lr()
        if self.iteration == 0 and not self.history:
            self._log_and_checkpoint(lr)
        last_logged = self.iteration
        stopped_by = "timesteps"
        with StopOnSignal() as stop:
            try:
                while self.timesteps < cfg.timesteps:
                    if stop.requested:
                        stopped_by = stop.requested
                        break
                    if cfg.minutes is not None and self._wall() >= 60.0 * cfg.minutes:
                        stopped_by = "minutes"
                        break
                    lr = self._set_lr()
                    before = self.timesteps
                    s, g, c, ts = self.collect()
                    self.timesteps += ts
                    self.timesteps_paper += ts
                    self._losses.append(self.update(s, g, c))
                    self.iteration += 1
                    bar.update(self.timesteps - before)
                    if self.iteration % cfg.eval_every == 0:
                        row = self._log_and_checkpoint(lr)
                        last_logged = self.iteration
                        bar.set_postfix(success=f"{row['success_rate']:.2f}",
                                        C_s=f"{row['evaluations_per_second']:.0f}")
                if self.iteration != last_logged:
                    self._log_and_checkpoint(lr)
            finally:
                bar.close()
        return finish_run(self.run_dir, self.history, self.best, stopped_by,
                          self.timesteps, self.iteration,
                          extra_result={"skipped_steps": self.skipped_steps})


def train(cfg: TrainConfig, out: str | Path, resume: bool = False,
          progress: bool = True) -> TrainResult:
    """Train a midpoint policy with ``cfg`` into run directory ``out`` (``resume``
    continues the run saved there, replaying exactly what an uninterrupted run does)."""
    return Trainer(cfg, out, resume=resume, progress=progress).run()


def read_run_config(run_dir: str | Path) -> TrainConfig:
    """The :class:`TrainConfig` saved in a run directory."""
    doc = read_json(Path(run_dir) / CONFIG_FILE)
    if "config" not in doc:
        raise CorruptFileError(f"{Path(run_dir) / CONFIG_FILE} has no 'config' section")
    return TrainConfig.from_dict(doc["config"])
