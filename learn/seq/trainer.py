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

import dataclasses
import math
import random
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from finsler.infra.limits import check_count, check_number
from learn.base import MAX_DEPTH, LoadedPolicy, TrainResult
from learn.evaluation import EvalResult, check_pairs
from learn.loop import (
    RunLoop,
    best_record,
    eval_columns,
    load_run,
    load_weights,
    resolve_device,
)
from learn.registry import Method, deprecated_entry, register_method
from learn.run_config import (
    RunConfig,
    check_hidden,
    ensure_registered,
    package_versions,
    training_settings,
)
from learn.seq.env import (
    TIME_LIMITS,
    ZERO_ACTION_REWARD,
    GeodesicEnv,
    GeodesicVecEnv,
    env_spaces,
    move,
    observation,
)

__all__ = [
    "SEGMENT_RTOL",
    "TIME_LIMITS",
    "WALL_COLUMNS",
    "ZERO_ACTION_REWARD",
    "GeodesicEnv",
    "GeodesicVecEnv",
    "SeqConfig",
    "SeqEvalResult",
    "SeqPolicy",
    "SeqTrainer",
    "default_seq_config",
    "evaluate_seq",
    "load_seq_policy",
    "rollout",
    "train_seq",
]

#: Relative tolerance on the segment test ``C(p_i, p_i+1) <= eps`` of Seq's paths: every
#: step of eq. (57) has ``C = eps`` exactly in exact arithmetic, ``eps * (1 +- 1e-16)`` in
#: float64 (see `evaluate_seq`).
SEGMENT_RTOL = 1e-9


# ----------------------------------------------------------------------------------------
# Configuration
# ----------------------------------------------------------------------------------------
#: 16 batched copies of the environment: about 4x the steps per second of SB3's single
#: environment with the paper's settings on 2 cores, and 32 are no faster (PPO's minibatch
#: updates then dominate). The rollout per update stays SB3's 2048 steps (16 x 128).
_DEFAULT_N_ENVS = 16
_PAPER_ROLLOUT = 2048


@dataclass
class SeqConfig(RunConfig):
    """Every setting of one Seq run (saved as ``config.json``): the run fields of
    `learn.run_config.RunConfig` (``seed`` also seeds SB3's global generators and
    the environments, copy ``i`` with ``seed + i``; ``timesteps``: the budget of
    ALL-INCLUSIVE evaluations of F or C made by the environments, 3 per step and 2 per
    reset candidate; paper: 2e7 (Matsumoto, Panda), 8e7 (car-like) env steps; ``device``
    is SB3's networks', the environments run on numpy; ``depth``: episodes last at most
    ``2**depth`` steps, paper n = 2**D_max; ``eps``: the step cost of eq. (57) and the
    success threshold; ``eval_every``: all-inclusive timesteps between evaluations,
    checked after every rollout), then Seq's own. PPO settings not listed are
    stable-baselines3's defaults (normalised advantages, orthogonal initialisation, log-std
    initialised at 0, no target KL, no value clipping)."""

    config_methods: ClassVar[tuple[str, ...]] = ("seq",)
    run_defaults: ClassVar[Mapping[str, Any]] = {"eval_every": 200_000}

    reject_solved: bool = True
    """Redraw start/goal pairs already within eps (the authors' code does)."""
    lr: float = 3e-3
    """Adam learning rate (paper: 3e-3, searched over 3e-2, 3e-3, 3e-4)."""
    batch_size: int = 128
    """PPO minibatch size (paper: 128, searched over 64, 128, 256)."""
    gamma: float = 1.0
    """Discount factor (paper: 1)."""
    n_envs: int = _DEFAULT_N_ENVS
    """Environment copies stepped together (paper: SB3's single environment)."""
    n_steps: int = _PAPER_ROLLOUT // _DEFAULT_N_ENVS
    """Steps per copy per rollout; ``n_envs * n_steps`` = 2048, SB3's default rollout."""
    n_epochs: int = 10
    """PPO epochs per rollout (SB3 default)."""
    time_limit: str = "truncate"
    """What the step limit ``n`` is to PPO: ``truncate`` (gymnasium's ``truncated``: SB3
    bootstraps the last step with the critic's value) or ``terminate`` (the episode ends as
    if absorbed, no bootstrap: the authors' gym-0.21 code)."""
    gae_lambda: float = 0.95
    """GAE lambda (SB3 default)."""
    clip_range: float = 0.2
    """PPO clip range (SB3 default)."""
    ent_coef: float = 0.0
    """Entropy coefficient (SB3 default)."""
    vf_coef: float = 0.5
    """Value-loss coefficient (SB3 default)."""
    max_grad_norm: float = 0.5
    """Gradient clipping (SB3 default)."""
    hidden: tuple[int, ...] = (64, 64)
    """Hidden layers of the actor and of the critic (paper: 64, 64)."""
    activation: str = "tanh"
    """``tanh`` (paper, SB3's default) or ``relu``."""
    def validate(self) -> None:
        """Raise `finsler.InputError` naming the first impossible field of Seq's
        own (the run fields are [`RunConfig`][learn.RunConfig]'s to check)."""
        for name in ("batch_size", "n_envs", "n_steps", "n_epochs"):
            v = getattr(self, name)
            if v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if not (0 < self.lr < 1):
            raise InputError(f"lr must be in (0, 1), got {self.lr!r}")
        if self.time_limit not in TIME_LIMITS:
            raise InputError(f"time_limit must be one of {', '.join(TIME_LIMITS)}, got "
                             f"{self.time_limit!r}")
        if not (0 < self.gamma <= 1):
            raise InputError(f"gamma must be in (0, 1], got {self.gamma!r}")
        if not (0 <= self.gae_lambda <= 1):
            raise InputError(f"gae_lambda must be in [0, 1], got {self.gae_lambda!r}")
        if not (0 < self.clip_range < math.inf):
            raise InputError(f"clip_range must be positive and finite, got {self.clip_range!r}")
        for name in ("ent_coef", "vf_coef"):
            v = getattr(self, name)
            if not (0 <= v < math.inf):
                raise InputError(f"{name} must be finite and >= 0, got {v!r}")
        if not (0 < self.max_grad_norm < math.inf):
            raise InputError(f"max_grad_norm must be positive and finite, got "
                             f"{self.max_grad_norm!r}")
        check_hidden(self.hidden)
        if self.activation not in ("tanh", "relu"):
            raise InputError(f"activation must be one of tanh, relu; got {self.activation!r}")
        if self.n_envs * self.n_steps < 2:
            raise InputError("n_envs * n_steps must be at least 2 (PPO normalises advantages)")
        if self.batch_size > self.n_envs * self.n_steps:
            raise InputError(f"batch_size ({self.batch_size}) must not exceed the rollout "
                             f"n_envs * n_steps ({self.n_envs * self.n_steps})")

    @property
    def model_free(self) -> bool:
        """Seq uses values of F and C only (rewards, steps, termination)."""
        return True


def default_seq_config(env: str, **overrides: Any) -> SeqConfig:
    """The paper's Seq settings for ``env`` (appendix B.2; budget 2e7, car-like 8e7) with
    this toolkit's batched environments (``n_envs`` x ``n_steps`` = SB3's 2048-step
    rollout); ``overrides`` replace fields (unknown ones raise `InputError`)."""
    ensure_registered(env, overrides.get("metric_class"))
    # the paper's budget for the metric's task (Metric.training.paper_timesteps)
    settings: dict[str, Any] = {"env": env,
                                "timesteps": training_settings(env).paper_timesteps}
    if "n_envs" in overrides and "n_steps" not in overrides:
        n = overrides["n_envs"]
        if isinstance(n, int) and not isinstance(n, bool) and n >= 1:
            settings["n_steps"] = max(1, _PAPER_ROLLOUT // n)
    settings.update(overrides)
    names = {f.name for f in dataclasses.fields(SeqConfig)}
    unknown = sorted(set(settings) - names)
    if unknown:
        raise InputError(f"unknown config field(s): {', '.join(unknown)}")
    return SeqConfig(**settings)


def _paper_differences(cfg: SeqConfig) -> dict[str, dict[str, Any]]:
    paper = {"lr": 3e-3, "batch_size": 128, "gamma": 1.0, "n_envs": 1, "n_steps": 2048,
             "n_epochs": 10, "gae_lambda": 0.95, "clip_range": 0.2, "ent_coef": 0.0,
             "vf_coef": 0.5, "max_grad_norm": 0.5, "hidden": [64, 64], "activation": "tanh"}
    d = cfg.to_dict()
    return {k: {"used": d[k], "paper": v} for k, v in paper.items() if d[k] != v}


def _run_document(cfg: SeqConfig) -> dict[str, Any]:
    """``config.json``'s sections about Seq."""
    import gymnasium as gym
    import stable_baselines3 as sb3

    return {
        "model_free": True,
        "uses_derivative_of_C": [],
        "counts": "timesteps = every evaluation of F or C made by the environments during "
                  "training (3 per step with a non-zero action, 0 for a zero action, 2 per "
                  "start/goal candidate at a reset); timesteps_paper = environment steps "
                  "(the paper's count); timesteps_derivative = 0",
        "selection": f"checkpoint_best by success on finsler.validation_pairs (seed "
                     f"{finsler.VALIDATION_SEED}, {cfg.eval_pairs} pairs)",
        "success": "path p_0..p_j, g (at most 2**D segments) with every C <= eps * "
                   f"(1 + {SEGMENT_RTOL:g}); reached_rate = the paper's episode success "
                   "(C(p_j, g) < eps within 2**D steps)",
        "versions": {**package_versions(), "stable_baselines3": sb3.__version__,
                     "gymnasium": gym.__version__},
        "beyond_paper": _paper_differences(cfg),
    }


# ----------------------------------------------------------------------------------------
# Deterministic rollouts and the section 5.1 evaluation
# ----------------------------------------------------------------------------------------
def _policy_fn(policy: Any) -> Any:
    """``obs (K, 2 dim) float32 -> actions (K, dim) float64``: the deterministic (mean)
    action of an SB3 policy, clipped to the action box as SB3 does."""
    def act(obs: np.ndarray) -> np.ndarray:
        a, _ = policy.predict(obs, deterministic=True)
        return np.asarray(a, dtype=np.float64).reshape(obs.shape[0], -1)
    return act


def rollout(act: Any, metric: finsler.Metric, starts: np.ndarray, goals: np.ndarray,
            eps: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """Walk every pair with the policy ``act`` (``obs (K, 2 dim) -> v (K, dim)``), all
    pairs at once, for at most ``steps`` steps of eq. (57), each pair stopping once
    ``C(p_j, g) < eps`` (tested from ``j = 0``).

    Returns ``points (K, steps + 1, dim)`` (after a pair stops its last point is repeated)
    and ``reached_at (K,)``: the first ``j`` with ``C(p_j, g) < eps``, or -1.
    """
    s = np.asarray(starts, np.float64)
    g = np.asarray(goals, np.float64)
    k = s.shape[0]
    pts = np.empty((k, steps + 1, metric.dim))
    pts[:, 0] = s
    reached_at = np.where(np.asarray(metric.cost(s, g)) < eps, 0, -1)
    p = s.copy()
    for j in range(1, steps + 1):
        active = np.flatnonzero(reached_at < 0)
        if active.size:
            v = act(observation(p[active], g[active]))
            q, moved, _ = move(metric, eps, p[active], v)
            p[active] = q
            mv = active[moved]
            if mv.size:
                hit = np.asarray(metric.cost(p[mv], g[mv])) < eps
                reached_at[mv[hit]] = j
        pts[:, j] = p
    return pts, reached_at


@dataclass
class SeqEvalResult(EvalResult):
    """`learn.evaluation.EvalResult` of Seq paths, plus the paper's episode success."""

    reached: np.ndarray = dataclasses.field(repr=False)
    """(K,) bool: ``C(p_j, g) < eps`` for some ``j <= 2**D`` (the paper's success for Seq,
    as in the authors' evaluation code)."""
    steps: np.ndarray = dataclasses.field(repr=False)
    """(K,) int: steps taken until reaching (``2**D`` if never reached)."""
    strict_success: np.ndarray = dataclasses.field(repr=False)
    """(K,) bool: `learn.evaluation.evaluate_paths`' test without any tolerance."""

    @property
    def reached_rate(self) -> float:
        return float(self.reached.mean())

    @property
    def strict_success_rate(self) -> float:
        return float(self.strict_success.mean())

    def to_dict(self) -> dict[str, Any]:
        d = super().to_dict()
        d["reached_rate"] = self.reached_rate
        d["strict_success_rate"] = self.strict_success_rate
        d["segment_rtol"] = SEGMENT_RTOL
        for row, r, n, st in zip(d["per_pair"], self.reached, self.steps, self.strict_success):
            row.update(reached=bool(r), steps=int(n), strict_success=bool(st))
        return d


def _paths_from_rollout(pts: np.ndarray, reached_at: np.ndarray, goals: np.ndarray,
                        n: int) -> np.ndarray:
    """``(K, n + 1, dim)`` paths ending at the goal: ``p_0..p_j, g, ..., g`` if reached at
    ``j <= n - 1``; otherwise ``p_0..p_{n-1}, g``."""
    paths = pts[:, : n + 1].copy()
    for i in range(paths.shape[0]):
        j = int(reached_at[i])
        start = j + 1 if 0 <= j <= n - 1 else n
        paths[i, start:] = goals[i]
    return paths


def evaluate_seq(act: Any, metric: finsler.Metric, pairs: np.ndarray, eps: float,
                 depth: int) -> tuple[SeqEvalResult, np.ndarray]:
    """Section 5.1 evaluation of a Seq policy on ``pairs`` ``(K, 2, dim)``: returns the
    result and the paths ``(K, 2**depth + 1, dim)``.

    The deterministic policy walks at most ``n = 2**depth`` steps (the training episode).
    The path is ``p_0..p_j, g`` padded with ``g`` when ``C(p_j, g) < eps`` at some
    ``j <= n - 1`` (at most n segments, the task of section 5.1), else
    ``p_0..p_{n-1}, g``.

    * ``success``: reached at ``j <= n - 1`` AND every segment ``C(p_i, p_i+1) <=
      eps * (1 + SEGMENT_RTOL)``. A step of eq. (57) has ``C = eps`` exactly in exact
      arithmetic; in float64 ``F(p, (p + eps/F(p,v) v) - p)`` is ``eps (1 +- 1e-16)``, so
      `learn.evaluation.evaluate_paths`' ``C <= eps`` would fail about half of the steps
      by rounding alone. The tolerance (1e-9 relative, 10^7 times the rounding, far below
      any change of the path) accepts exactly those; a step whose projection into the
      domain really raised its cost above eps still fails. The last segment is ``< eps``
      by the reach test, padding segments cost 0.
    * ``strict_success``: ``evaluate_paths``' test with no tolerance (shows the rounding).
    * ``reached``: the paper's/authors' success for Seq: ``C(p_j, g) < eps`` within the
      ``n`` steps of an episode (one more step than fits in n segments; no segment test).
    """
    check_count(depth, "depth", 0, MAX_DEPTH)
    check_number(eps, "eps", 0.0, low_open=True)
    t0 = time.perf_counter()
    n = 2 ** int(depth)
    pts, reached_at = rollout(act, metric, pairs[:, 0], pairs[:, 1], float(eps), n)
    paths = _paths_from_rollout(pts, reached_at, pairs[:, 1], n)
    costs = np.asarray(metric.path_costs(paths))
    mx = costs.max(axis=1)
    length = costs.sum(axis=1)
    within = (reached_at >= 0) & (reached_at <= n - 1)
    ok = within & np.all(costs <= eps * (1.0 + SEGMENT_RTOL), axis=1)
    steps = np.where(reached_at >= 0, reached_at, n)
    res = SeqEvalResult(
        success_rate=float(ok.mean()),
        mean_length=float(length.mean()),
        mean_max_segment_cost=float(mx.mean()),
        eps=float(eps),
        depth=int(depth),
        success=ok,
        length=length,
        max_segment_cost=mx,
        reached=reached_at >= 0,
        steps=steps,
        strict_success=mx <= eps,
        wall_time=time.perf_counter() - t0,
    )
    return res, paths


# ----------------------------------------------------------------------------------------
# Loaded policies
# ----------------------------------------------------------------------------------------
def _build_policy(cfg: SeqConfig, device: str = "cpu") -> Any:
    """An SB3 ``ActorCriticPolicy`` exactly as ``PPO("MlpPolicy", ...)`` builds it for
    ``cfg`` (untrained)."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    obs, act = env_spaces(cfg.metric)
    lr = cfg.lr
    return ActorCriticPolicy(obs, act, lambda _: lr, **_policy_kwargs(cfg)).to(
        resolve_device(device))


def _policy_kwargs(cfg: SeqConfig) -> dict[str, Any]:
    act = torch.nn.Tanh if cfg.activation == "tanh" else torch.nn.ReLU
    return {"net_arch": {"pi": list(cfg.hidden), "vf": list(cfg.hidden)}, "activation_fn": act}


class SeqPolicy(LoadedPolicy):
    """A trained Seq policy (deterministic mean actions) for one metric; generates paths
    like [`learn.midpoint.policy.Policy`][learn.midpoint.policy.Policy]."""

    def __init__(self, policy: Any, config: SeqConfig, source: str = "",
                 checkpoint: str = "") -> None:
        super().__init__(config, source, checkpoint)
        self.policy = policy
        self.policy.set_training_mode(False)

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """Paths ``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)`` float64 (D = ``depth`` or the
        task's): the deterministic walk ``p_0..p_j`` until ``C(p_j, g) < eps`` (at most
        ``2**D - 1`` steps fit), then ``g`` repeated; a pair that does not get there
        within that many steps gets ``p_0..p_{n-1}, g`` (its last segment shows how far
        it was). Starts are ``p_0``, goals the last point."""
        d = self.check_depth(depth)
        s = self.metric.domain.check(starts, "starts")
        g = self.metric.domain.check(goals, "goals")
        if s.shape != g.shape:
            raise InputError(f"starts and goals differ in shape: {s.shape} vs {g.shape}")
        n = 2**d
        pts, reached_at = rollout(_policy_fn(self.policy), self.metric, s, g, self.eps, n)
        return _paths_from_rollout(pts, reached_at, g, n)

    def evaluate(self, pairs: Any = None, eps: float | None = None,
                 depth: int | None = None) -> SeqEvalResult:
        """Section 5.1 evaluation on ``pairs`` ``(K, 2, dim)`` (default:
        ``finsler.default_pairs``); ``eps`` is both the step cost of the walk and the
        success threshold. See `evaluate_seq` for how success relates to
        `learn.evaluation.evaluate_paths`."""
        p = finsler.default_pairs(self.metric) if pairs is None else check_pairs(
            self.metric, pairs)
        e = self.eps if eps is None else eps
        res, _ = evaluate_seq(_policy_fn(self.policy), self.metric, p, e, self.check_depth(depth))
        return res


def load_seq_policy(run_dir: str | Path, checkpoint: str = "best",
                    device: str = "cpu", env: str | None = None,
                    metric_params: dict[str, Any] | None = None) -> SeqPolicy:
    """Load the Seq policy of a run directory: ``checkpoint`` ``best`` (best validation
    success; falls back to the latest) or ``latest``; ``env`` / ``metric_params``, if
    given, must be the run's (`learn.run_config.check_run_metric`)."""
    path, cfg, ckpt, name = load_run(run_dir, checkpoint, SeqConfig, ("seq",), env,
                                     metric_params)
    policy = _build_policy(cfg, device)
    load_weights(policy, ckpt.get("policy"), path)
    return SeqPolicy(policy, cfg, source=str(path), checkpoint=name)


# ----------------------------------------------------------------------------------------
# Training
# ----------------------------------------------------------------------------------------
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
            policy_kwargs=_policy_kwargs(cfg), seed=cfg.seed, device=self.device, verbose=0)
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
        return _run_document(self.cfg)

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
        res, _ = evaluate_seq(_policy_fn(self.model.policy), self.metric, p,
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
