"""The paper's sequential RL baseline "Seq" (section 5.2, appendix B.2): goal-conditioned PPO.

stable-baselines3's PPO, with the paper's hyperparameters, on the goal-conditioned walk of
eqs. (57) and (14) (`learn.seq.env`: `GeodesicEnv`, and `GeodesicVecEnv`
that steps ``n_envs`` copies with one vectorised evaluation of ``F`` per quantity).
`SeqTrainer` trains it into a run directory of the shared contract
(``config.json``, ``metrics.csv``, ``checkpoint_latest.pt``, ``checkpoint_best.pt``,
``result.json``; the loop is [`learn.loop.RunLoop`][learn.loop.RunLoop]'s); `load_seq_policy`
loads a `SeqPolicy` that generates and evaluates paths like
[`learn.midpoint.policy.Policy`][learn.midpoint.policy.Policy].

**Counting.** ``timesteps`` (the budget) counts every evaluation of ``F`` or ``C`` the
environments make, whatever for (3 per step with a non-zero action, 0 for a zero action,
2 per sampled start/goal candidate at a reset: `learn.seq.env`); ``timesteps_paper``
counts environment steps (the paper's count, section 5.2), so ``timesteps`` is about 3x
``timesteps_paper``. The validation rollouts are not training and are not counted.

**Departures and choices** (all recorded in ``config.json``): like the authors' code
(``scripts/gym_env_wrapper.py`` of omron-sinicx/midpoint_learning) a start/goal pair that
is already solved (``C(s, g) < eps``) is redrawn (``reject_solved``), and SB3 clips the
Gaussian actions to the action box ``[-1, 1]**dim`` before they reach the environment.
The truncation at ``n`` steps is reported to SB3 as a time limit (gymnasium's
``truncated``), so SB3 bootstraps it with the value of the last observation; the authors'
gym-0.21 code ended such episodes as plain terminations.
"""

from __future__ import annotations

import random
from pathlib import Path
from typing import Any

import numpy as np
import torch

from learn.base import TrainResult
from learn.loop import RunLoop, best_record, eval_columns
from learn.registry import Method, deprecated_entry, register_method
from learn.seq.config import SeqConfig, default_seq_config, run_document
from learn.seq.env import GeodesicVecEnv
from learn.seq.policy import (
    SeqEvalResult,
    evaluate_seq,
    load_seq_policy,
    mean_actions,
    policy_kwargs,
)

__all__ = ["WALL_COLUMNS", "SeqTrainer", "train_seq"]

_TRAIN_KEYS = {
    "policy_loss": "train/policy_gradient_loss",
    "value_loss": "train/value_loss",
    "entropy_loss": "train/entropy_loss",
    "approx_kl": "train/approx_kl",
    "clip_fraction": "train/clip_fraction",
    "std": "train/std",
    "explained_variance": "train/explained_variance",
}
#: Columns that depend on the machine's speed (excluded from determinism checks).
WALL_COLUMNS = ("wall_seconds", "evaluations_per_second", "steps_per_second")


class SeqTrainer(RunLoop):
    """PPO (stable-baselines3) on `GeodesicVecEnv` into a run directory (the loop:
    [`learn.loop.RunLoop`][learn.loop.RunLoop]).

    One iteration = one SB3 rollout of ``n_envs * n_steps`` steps and its PPO update
    (``model.learn`` for exactly one rollout, ``reset_num_timesteps=False``: SB3's own
    loop, cut into rollouts so that budgets, evaluations and checkpoints fall between
    rollouts). The learning rate and clip range are constant (the paper's settings), so
    this is the same computation as one long ``learn`` call. A metrics row is written
    every ``eval_every`` all-inclusive timesteps (checked after each rollout).
    """

    config_class = SeqConfig
    label = "seq"

    def setup(self) -> None:
        from stable_baselines3 import PPO
        from stable_baselines3.common.logger import Logger

        cfg = self.cfg
        self.eval_pairs = self.validation_pairs
        self.venv = GeodesicVecEnv(self.metric, cfg.n_envs, eps=cfg.eval_eps,
                                   depth=cfg.max_depth, reject_solved=cfg.reject_solved,
                                   time_limit=cfg.time_limit)
        self.model = PPO(
            "MlpPolicy", self.venv, learning_rate=cfg.lr, n_steps=cfg.n_steps,
            batch_size=cfg.batch_size, n_epochs=cfg.n_epochs, gamma=cfg.gamma,
            gae_lambda=cfg.gae_lambda, clip_range=cfg.clip_range, ent_coef=cfg.ent_coef,
            vf_coef=cfg.vf_coef, max_grad_norm=cfg.max_grad_norm,
            policy_kwargs=policy_kwargs(cfg), seed=cfg.seed, device=self.device, verbose=0)
        self.model.set_logger(Logger(folder=None, output_formats=[]))
        self.next_eval = 0
        self._ep_mark = (0, 0)  # (episodes, successes) at the last metrics row

    def start(self) -> None:
        # the first reset, as SB3's first ``learn`` would do it (seeds seed + i)
        self.model._last_obs = self.venv.reset()
        self.model._last_episode_starts = np.ones(self.cfg.n_envs, dtype=bool)
        self._sync_counters()
        self.next_eval = self.cfg.eval_every  # the first row is at iteration 0

    def _sync_counters(self) -> None:
        """``timesteps``: all-inclusive evaluations of F or C of the environments;
        ``timesteps_paper``: their steps (the paper's count)."""
        self.timesteps = self.venv.evaluations
        self.timesteps_paper = self.venv.env_steps

    # -- state ----------------------------------------------------------------------------
    def state_dict(self) -> dict[str, Any]:
        m = self.model
        np_state = np.random.get_state(legacy=False)  # noqa: NPY002 (SB3's generator)
        return {
            "policy": m.policy.state_dict(),
            "optimizer": m.policy.optimizer.state_dict(),
            "env": self.venv.get_state(),
            "sb3": {
                "num_timesteps": int(m.num_timesteps),
                "n_updates": int(m._n_updates),
                "last_obs": torch.from_numpy(np.asarray(m._last_obs).copy()),
                "last_episode_starts": torch.from_numpy(
                    np.asarray(m._last_episode_starts).copy()),
            },
            "rng": {
                "torch": torch.get_rng_state(),
                "numpy": {"state": {"key": torch.from_numpy(
                    np_state["state"]["key"].astype(np.int64)),
                    "pos": int(np_state["state"]["pos"])},
                    "has_gauss": int(np_state["has_gauss"]),
                    "gauss": float(np_state["gauss"])},
                "python": random.getstate(),
            },
            "counters": {"next_eval": self.next_eval, "episodes_mark": list(self._ep_mark)},
        }

    def load_state_dict(self, st: dict[str, Any]) -> None:
        m = self.model
        m.policy.load_state_dict(st["policy"])
        m.policy.optimizer.load_state_dict(st["optimizer"])
        self.venv.set_state(st["env"])
        sb = st["sb3"]
        m.num_timesteps = int(sb["num_timesteps"])
        m._n_updates = int(sb["n_updates"])
        m._last_obs = sb["last_obs"].numpy().copy()
        m._last_episode_starts = sb["last_episode_starts"].numpy().copy()
        rng = st["rng"]
        torch.set_rng_state(rng["torch"])
        npst = rng["numpy"]
        np.random.set_state({  # noqa: NPY002 (SB3 samples from the global one)
            "bit_generator": "MT19937",
            "state": {"key": npst["state"]["key"].numpy().astype(np.uint32),
                      "pos": int(npst["state"]["pos"])},
            "has_gauss": int(npst["has_gauss"]), "gauss": float(npst["gauss"])})
        py = rng["python"]
        random.setstate((py[0], tuple(py[1]), py[2]))
        c = st["counters"]
        self.next_eval = int(c["next_eval"])
        self._ep_mark = (int(c["episodes_mark"][0]), int(c["episodes_mark"][1]))
        self._sync_counters()

    def policy_state(self) -> dict[str, Any]:
        return {"policy": self.model.policy.state_dict()}

    def run_document(self) -> dict[str, Any]:
        return run_document(self.cfg)

    # -- one rollout + update -------------------------------------------------------------
    def iterate(self) -> None:
        self.train_rollout()

    def train_rollout(self) -> None:
        """Collect one rollout of ``n_envs * n_steps`` steps and run PPO's update on it."""
        self.model.learn(total_timesteps=self.cfg.n_envs * self.cfg.n_steps,
                         reset_num_timesteps=False, log_interval=None, progress_bar=False)
        self.iteration += 1
        self._sync_counters()

    def evaluation_due(self) -> bool:
        if self.timesteps < self.next_eval:
            return False
        while self.next_eval <= self.timesteps:
            self.next_eval += self.cfg.eval_every
        return True

    # -- evaluation -----------------------------------------------------------------------
    def evaluate(self, pairs: np.ndarray | None = None) -> SeqEvalResult:
        """Deterministic policy on the validation set (all pairs at once)."""
        p = self.eval_pairs if pairs is None else pairs
        res, _ = evaluate_seq(mean_actions(self.model.policy), self.metric, p,
                              self.cfg.eval_eps, self.cfg.max_depth)
        self.model.policy.set_training_mode(False)
        return res

    def evaluation(self) -> tuple[dict[str, Any], dict[str, Any]]:
        ev = self.evaluate()
        logged = self.model.logger.name_to_value if self.iteration > 0 else {}
        eps_done = self.venv.episodes - self._ep_mark[0]
        succ = self.venv.successes - self._ep_mark[1]
        self._ep_mark = (self.venv.episodes, self.venv.successes)
        columns: dict[str, Any] = {
            **eval_columns(ev),
            "reached_rate": ev.reached_rate,
            "strict_success_rate": ev.strict_success_rate,
            "mean_steps": float(np.mean(ev.steps)),
            "train_episodes": eps_done,
            "train_success_rate": round(succ / eps_done, 6) if eps_done else float("nan"),
        }
        for col, key in _TRAIN_KEYS.items():
            columns[col] = float(logged[key]) if key in logged else float("nan")
        columns["lr"] = self.cfg.lr
        return columns, best_record(ev, reached_rate=ev.reached_rate,
                                    timesteps=self.timesteps,
                                    timesteps_paper=self.timesteps_paper,
                                    iteration=self.iteration)

    def rates(self, wall: float) -> dict[str, Any]:
        return {"steps_per_second": round(self.timesteps_paper / max(wall, 1e-9), 1)}

    def progress_fields(self, row: dict[str, Any]) -> dict[str, Any]:
        return {"success": f"{row['success_rate']:.2f}",
                "steps_s": f"{row['steps_per_second']:.0f}"}


def train_seq(cfg: SeqConfig, out: str | Path, resume: bool = False,
              progress: bool = True) -> TrainResult:
    """Deprecated: `learn.train_run` (the one entry point for every method) trains
    ``cfg`` the same way. Train Seq (PPO, appendix B.2) with ``cfg`` into run directory
    ``out``.

    Every ``eval_every`` all-inclusive timesteps (checked after each rollout) the
    deterministic policy is evaluated on ``finsler.validation_pairs`` (all pairs rolled
    out together), a metrics row is appended, ``checkpoint_best.pt`` (best success, ties
    by lower mean max segment cost) and ``checkpoint_latest.pt`` are written; at the end
    ``result.json``. Refuses a non-empty ``out`` unless ``resume``.

    **Resume** continues from ``checkpoint_latest.pt`` (written at every evaluation, i.e.
    between rollouts), dropping metrics rows written after it. The checkpoint holds the
    policy and Adam states, SB3's counters and its last observation/episode-start flags,
    the environments' points, goals, step counts, carried distances and generators, and the
    global torch / numpy / python generator states SB3 samples from (actions, minibatch
    order). Resumed, the run is bit-identical to an uninterrupted one on the same machine
    and settings (tested), except SB3's ``ep_info_buffer`` statistics (not used here) and
    wall-time columns. Work done after the last checkpoint is redone, not lost in
    outcome. SB3 uses the process-global generators, which this function seeds
    (``seed``) and leaves advanced.
    """
    deprecated_entry("learn.seq.train_seq")
    return SeqTrainer(cfg, out, resume=resume, progress=progress).run()


register_method(Method(
    name="seq",
    summary="goal-conditioned PPO on a gymnasium environment (eqs. 14, 57)",
    config_class=SeqConfig,
    trainer=SeqTrainer,
    load_policy=load_seq_policy,
    default_config=default_seq_config,
))
