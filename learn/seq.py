"""The paper's sequential RL baseline "Seq" (section 5.2, appendix B.2): goal-conditioned PPO.

The agent walks from a start ``s`` to a goal ``g`` in steps of local cost ``eps``:

* observation ``(p, g)`` (``2 * dim``), action a direction ``v`` (``dim``, in ``[-1, 1]``);
* next point, eq. (57): ``q = p + eps / F(p, v) * v``, projected into the domain (the
  coordinates are the chart, so ``df`` is the identity);
* reward, eq. (14): ``R = F(g, g - p) - F(g, g - q) - eps``; a zero action leaves ``p``
  where it is and gives ``R = -100``;
* the episode terminates (success) when ``C(q, g) < eps`` and is truncated after
  ``n = 2**D`` steps (D: the task's depth).

:class:`GeodesicEnv` is that environment for any registered metric (gymnasium API);
:class:`GeodesicVecEnv` steps ``n_envs`` copies at once with one vectorised evaluation of
``F`` per quantity (a stable-baselines3 ``VecEnv`` with exactly the transitions of
``DummyVecEnv`` over :class:`GeodesicEnv`). :func:`train_seq` trains stable-baselines3's
PPO with the paper's hyperparameters into a run directory of the shared contract
(``config.json``, ``metrics.csv``, ``checkpoint_latest.pt``, ``checkpoint_best.pt``,
``result.json``); :func:`load_seq_policy` loads a :class:`SeqPolicy` that generates and
evaluates paths like :class:`learn.policy.Policy`.

**Counting.** ``timesteps`` (the budget) counts every evaluation of ``F`` or ``C`` the
environment makes, whatever for: per step with a non-zero action exactly 3 (``F(p, v)`` of
eq. (57), ``F(g, g - q)`` of eq. (14) and ``C(q, g)`` of the termination test;
``F(g, g - p)`` is carried over from the previous step), 0 for a zero action (nothing
changes), and 2 per sampled start/goal candidate at a reset (``F(g, g - s)`` and
``C(s, g)``; 1 for a reset to given points, which training never does).
``timesteps_paper`` counts environment steps (the paper's count, section 5.2), so
``timesteps`` is about 3x ``timesteps_paper``. The validation rollouts are not training
and are not counted.

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
import json
import math
import random
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

import finsler
from finsler.errors import InputError
from learn.base import StopOnSignal, TrainResult, check_hidden, finish_run
from learn.config import (
    MetricConfig,
    check_run_metric,
    ensure_registered,
    metric_info,
    package_versions,
)
from learn.networks import resolve_device
from learn.policy import EvalResult, check_pairs
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

__all__ = [
    "SEGMENT_RTOL",
    "ZERO_ACTION_REWARD",
    "GeodesicEnv",
    "GeodesicVecEnv",
    "SeqConfig",
    "SeqEvalResult",
    "SeqPolicy",
    "default_seq_config",
    "evaluate_seq",
    "load_seq_policy",
    "rollout",
    "train_seq",
]

#: Reward of a zero action (appendix B.2); the point does not move.
ZERO_ACTION_REWARD = -100.0
TIME_LIMITS = ("truncate", "terminate")
"""How the step limit may end an episode (see :class:`SeqConfig`.time_limit)."""
#: Relative tolerance on the segment test ``C(p_i, p_i+1) <= eps`` of Seq's paths: every
#: step of eq. (57) has ``C = eps`` exactly in exact arithmetic, ``eps * (1 +- 1e-16)`` in
#: float64 (see :func:`evaluate_seq`).
SEGMENT_RTOL = 1e-9
_MAX_RESAMPLE_ROUNDS = 1000


# ----------------------------------------------------------------------------------------
# The transition of eqs. (57) and (14), batch-first, float64
# ----------------------------------------------------------------------------------------
def _metric_of(metric: finsler.Metric | str) -> finsler.Metric:
    return metric if isinstance(metric, finsler.Metric) else finsler.get_metric(metric)


def _move(metric: finsler.Metric, eps: float, p: np.ndarray,
          v: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Eq. (57) for rows ``p, v`` ``(N, dim)`` float64: ``q = proj(p + eps / F(p, v) * v)``.

    Rows with ``v == 0`` stay (``q = p``), as do rows where ``F(p, v)`` is not positive and
    finite (impossible for a Finsler metric; guarded, not silently divided by).
    Returns ``(q (N, dim), moved (N,) bool, evaluations of F)``.
    """
    q = p.copy()
    moved = np.any(v != 0.0, axis=1)
    idx = np.flatnonzero(moved)
    if idx.size == 0:
        return q, moved, 0
    f = np.asarray(metric.F(p[idx], v[idx]), dtype=np.float64)
    ok = np.isfinite(f) & (f > 0.0)
    good = idx[ok]
    if good.size:
        q[good] = metric.domain.project(p[good] + (eps / f[ok])[:, None] * v[good])
    moved[idx[~ok]] = False
    return q, moved, int(idx.size)


def _transition(metric: finsler.Metric, eps: float, p: np.ndarray, g: np.ndarray,
                v: np.ndarray, dist: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """One step of every row: points ``p``, goals ``g``, actions ``v`` ``(N, dim)`` and the
    carried ``dist = F(g, g - p)`` ``(N,)``.

    Returns ``(q, reward, F(g, g - q), reached = C(q, g) < eps, evaluations)``; a row that
    did not move gets ``R = -100``, keeps its ``dist`` and is not reached (its point was
    tested at the previous step or at the reset).
    """
    q, moved, n_eval = _move(metric, eps, p, v)
    reward = np.full(p.shape[0], ZERO_ACTION_REWARD)
    new_dist = dist.copy()
    reached = np.zeros(p.shape[0], dtype=bool)
    idx = np.flatnonzero(moved)
    if idx.size:
        gm, qm = g[idx], q[idx]
        d = gm - qm
        # F(g, g - q) (eq. 14) and C(q, g) = F(q, g - q) in one vectorised call
        both = np.asarray(metric.F(np.concatenate([gm, qm]), np.concatenate([d, d])))
        k = idx.size
        new_dist[idx] = both[:k]
        reward[idx] = dist[idx] - both[:k] - eps
        reached[idx] = both[k:] < eps
        n_eval += 2 * k
    return q, reward, new_dist, reached, n_eval


def _sample_pairs(metric: finsler.Metric, eps: float, rngs: list[np.random.Generator],
                  reject_solved: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """One start/goal pair per generator (``domain.sample(2, rng)``: row 0 the start, row 1
    the goal), redrawn while ``C(s, g) < eps`` if ``reject_solved``.

    Returns ``(starts, goals (K, dim), F(g, g - s) (K,), evaluations)``.
    """
    k, dim = len(rngs), metric.dim
    s, g, dist = np.empty((k, dim)), np.empty((k, dim)), np.empty(k)
    pending = np.arange(k)
    n_eval = 0
    for _ in range(_MAX_RESAMPLE_ROUNDS):
        for i in pending:
            pts = metric.domain.sample(2, rngs[i])
            s[i], g[i] = pts[0], pts[1]
        gp, sp = g[pending], s[pending]
        d = gp - sp
        both = np.asarray(metric.F(np.concatenate([gp, sp]), np.concatenate([d, d])))
        m = pending.size
        dist[pending] = both[:m]
        n_eval += 2 * m
        pending = pending[both[m:] < eps] if reject_solved else pending[:0]
        if pending.size == 0:
            return s, g, dist, n_eval
    raise InputError(f"eps = {eps!r} is too large for {metric.name}: {_MAX_RESAMPLE_ROUNDS} "
                     "uniform start/goal pairs in a row were already within eps")


def _spaces(metric: finsler.Metric) -> tuple[spaces.Box, spaces.Box]:
    """Observation box ``(p, g)`` from the domain's bounds and action box ``[-1, 1]**dim``
    (float32, as SB3's networks use)."""
    lo, hi = metric.domain.bounds()
    lo2 = np.concatenate([lo, lo]).astype(np.float32)
    hi2 = np.concatenate([hi, hi]).astype(np.float32)
    obs = spaces.Box(lo2, hi2, dtype=np.float32)
    act = spaces.Box(-np.ones(metric.dim, np.float32), np.ones(metric.dim, np.float32),
                     dtype=np.float32)
    return obs, act


def _obs(p: np.ndarray, g: np.ndarray) -> np.ndarray:
    return np.concatenate([p, g], axis=-1).astype(np.float32)


def _check_action(a: Any, n: int, dim: int) -> np.ndarray:
    """Actions as float64 ``(n, dim)``; :class:`InputError` for a wrong size or NaN/inf."""
    if np.size(a) != n * dim:
        raise InputError(f"action must have {dim} components per environment ({n}), got "
                         f"shape {np.shape(a)}")
    v = np.asarray(a, dtype=np.float64).reshape(n, dim)
    if not np.all(np.isfinite(v)):
        raise InputError("action contains NaN or inf")
    return v


# ----------------------------------------------------------------------------------------
# Environments
# ----------------------------------------------------------------------------------------
class GeodesicEnv(gymnasium.Env):
    """Goal-conditioned walk of eqs. (57) and (14) on any metric (gymnasium API).

    Parameters: ``metric`` (a :class:`finsler.Metric` or a registered name), ``eps``
    (step cost and success threshold; default the task's), ``depth`` (the episode lasts at
    most ``2**depth`` steps; default the task's), ``reject_solved`` (redraw start/goal
    pairs with ``C(s, g) < eps``, as the authors' code does).

    ``reset(seed=..., options={"start": s, "goal": g})`` starts from given points (no
    redraw). The state is float64; observations are float32 ``(2 * dim,)``. Counters:
    :attr:`evaluations` (every evaluation of F or C, see the module docstring) and
    :attr:`env_steps` (steps taken, the paper's count). ``info["is_success"]`` marks the
    terminating step, ``info["evaluations"]`` the evaluations of this call.
    """

    metadata: dict[str, Any] = {"render_modes": []}  # noqa: RUF012 (gymnasium's API)

    def __init__(self, metric: finsler.Metric | str = "matsumoto", eps: float | None = None,
                 depth: int | None = None, reject_solved: bool = True,
                 render_mode: str | None = None, time_limit: str = "truncate") -> None:
        super().__init__()
        if time_limit not in TIME_LIMITS:
            raise InputError(f"time_limit must be one of {', '.join(TIME_LIMITS)}, got "
                             f"{time_limit!r}")
        self.time_limit = time_limit
        self.metric = _metric_of(metric)
        self.eps = float(self.metric.task.eps if eps is None else eps)
        self.depth = int(self.metric.task.depth if depth is None else depth)
        if not (math.isfinite(self.eps) and self.eps > 0):
            raise InputError(f"eps must be positive and finite, got {eps!r}")
        if self.depth < 0:
            raise InputError(f"depth must be a non-negative integer, got {depth!r}")
        if render_mode is not None:
            raise InputError("GeodesicEnv has no render modes")
        self.render_mode = render_mode
        self.max_steps = 2**self.depth
        self.reject_solved = bool(reject_solved)
        self.observation_space, self.action_space = _spaces(self.metric)
        self.evaluations = 0
        self.env_steps = 0
        self._p = np.zeros((1, self.metric.dim))
        self._g = np.zeros((1, self.metric.dim))
        self._dist = np.zeros(1)
        self._t = 0

    @property
    def point(self) -> np.ndarray:
        """Current point ``(dim,)`` float64."""
        return self._p[0].copy()

    @property
    def goal(self) -> np.ndarray:
        """Goal ``(dim,)`` float64."""
        return self._g[0].copy()

    def reset(self, *, seed: int | None = None,
              options: dict[str, Any] | None = None) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        options = options or {}
        if "start" in options or "goal" in options:
            s = self.metric.domain.check(options.get("start"), "start").reshape(1, -1)
            g = self.metric.domain.check(options.get("goal"), "goal").reshape(1, -1)
            dist = np.asarray(self.metric.F(g, g - s)).reshape(1)
            n_eval = 1
        else:
            s, g, dist, n_eval = _sample_pairs(self.metric, self.eps, [self.np_random],
                                               self.reject_solved)
        self._p, self._g, self._dist, self._t = s.copy(), g.copy(), dist, 0
        self.evaluations += n_eval
        return _obs(self._p, self._g)[0], {"evaluations": n_eval}

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        v = _check_action(action, 1, self.metric.dim)
        q, reward, dist, reached, n_eval = _transition(self.metric, self.eps, self._p,
                                                       self._g, v, self._dist)
        self._p, self._dist = q, dist
        self._t += 1
        self.env_steps += 1
        self.evaluations += n_eval
        terminated = bool(reached[0])
        truncated = (not terminated) and self._t >= self.max_steps
        if truncated and self.time_limit == "terminate":
            terminated, truncated = True, False
        info = {"is_success": bool(reached[0]), "evaluations": n_eval}
        return _obs(self._p, self._g)[0], float(reward[0]), terminated, truncated, info


class GeodesicVecEnv(VecEnv):
    """``n_envs`` copies of :class:`GeodesicEnv` stepped together: one vectorised call of
    ``F`` per quantity for all copies instead of one per copy.

    Same transitions, rewards, infos and random streams as
    ``DummyVecEnv([lambda: GeodesicEnv(...)] * n_envs)``: copy ``i`` has its own
    generator, seeded with ``seed + i`` at the first :meth:`reset` after :meth:`seed`;
    finished copies are reset automatically and their last observation is in
    ``info["terminal_observation"]`` (SB3's convention). Rewards are float32 as in
    ``DummyVecEnv``. Counters: :attr:`evaluations` (all copies, all-inclusive),
    :attr:`env_steps` (steps of all copies), :attr:`episodes` and :attr:`successes`
    (finished and terminated training episodes).
    """

    def __init__(self, metric: finsler.Metric | str, n_envs: int, eps: float | None = None,
                 depth: int | None = None, reject_solved: bool = True,
                 time_limit: str = "truncate") -> None:
        if not isinstance(n_envs, (int, np.integer)) or n_envs < 1:
            raise InputError(f"n_envs must be a positive integer, got {n_envs!r}")
        proto = GeodesicEnv(metric, eps=eps, depth=depth, reject_solved=reject_solved,
                            time_limit=time_limit)
        self.time_limit = time_limit
        self.metric, self.eps, self.max_steps = proto.metric, proto.eps, proto.max_steps
        self.reject_solved = proto.reject_solved
        self.render_mode = None
        super().__init__(int(n_envs), proto.observation_space, proto.action_space)
        n, dim = self.num_envs, self.metric.dim
        self._p, self._g = np.zeros((n, dim)), np.zeros((n, dim))
        self._dist = np.zeros(n)
        self._t = np.zeros(n, dtype=np.int64)
        self._rngs: list[np.random.Generator | None] = [None] * n
        self._actions = np.zeros((n, dim))
        self.evaluations = 0
        self.env_steps = 0
        self.episodes = 0
        self.successes = 0

    # -- VecEnv API -----------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        for i in range(self.num_envs):
            if self._seeds[i] is not None or self._rngs[i] is None:
                self._rngs[i] = seeding.np_random(self._seeds[i])[0]
        self._reset_rows(np.arange(self.num_envs))
        self._reset_seeds()
        self._reset_options()
        return _obs(self._p, self._g)

    def _reset_rows(self, rows: np.ndarray) -> None:
        rngs = [self._rngs[i] for i in rows]
        s, g, dist, n_eval = _sample_pairs(self.metric, self.eps, rngs,  # type: ignore[arg-type]
                                           self.reject_solved)
        self._p[rows], self._g[rows], self._dist[rows] = s, g, dist
        self._t[rows] = 0
        self.evaluations += n_eval

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = _check_action(actions, self.num_envs, self.metric.dim)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        q, reward, dist, reached, n_eval = _transition(
            self.metric, self.eps, self._p, self._g, self._actions, self._dist)
        self._p, self._dist = q, dist
        self._t += 1
        self.env_steps += self.num_envs
        self.evaluations += n_eval
        truncated = ~reached & (self._t >= self.max_steps)
        dones = reached | truncated
        obs = _obs(self._p, self._g)
        infos: list[dict[str, Any]] = [
            {"is_success": bool(reached[i]),
             "TimeLimit.truncated": bool(truncated[i]) and self.time_limit == "truncate"}
            for i in range(self.num_envs)
        ]
        done_rows = np.flatnonzero(dones)
        if done_rows.size:
            for i in done_rows:
                infos[i]["terminal_observation"] = obs[i].copy()
            self.episodes += int(done_rows.size)
            self.successes += int(reached.sum())
            self._reset_rows(done_rows)
            obs[done_rows] = _obs(self._p[done_rows], self._g[done_rows])
        return obs, reward.astype(np.float32), dones, infos

    def close(self) -> None:
        pass

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        fn = getattr(self, method_name)
        return [fn(*method_args, **method_kwargs) for _ in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    # -- state for exact resume -----------------------------------------------------------
    def get_state(self) -> dict[str, Any]:
        """Everything that defines the future of the copies (tensors and plain data)."""
        return {
            "points": torch.from_numpy(self._p.copy()),
            "goals": torch.from_numpy(self._g.copy()),
            "dist": torch.from_numpy(self._dist.copy()),
            "t": torch.from_numpy(self._t.copy()),
            "rngs": [None if r is None else r.bit_generator.state for r in self._rngs],
            "counters": {"evaluations": self.evaluations, "env_steps": self.env_steps,
                         "episodes": self.episodes, "successes": self.successes},
        }

    def set_state(self, st: dict[str, Any]) -> None:
        n = self.num_envs
        p = st["points"].numpy().astype(np.float64)
        if p.shape != (n, self.metric.dim) or len(st["rngs"]) != n:
            raise ValueError(f"saved environment state is for {p.shape} points, not "
                             f"({n}, {self.metric.dim})")
        self._p, self._g = p, st["goals"].numpy().astype(np.float64)
        self._dist = st["dist"].numpy().astype(np.float64)
        self._t = st["t"].numpy().astype(np.int64)
        for i, s in enumerate(st["rngs"]):
            if s is None:
                self._rngs[i] = None
            else:
                r = np.random.Generator(np.random.PCG64())
                r.bit_generator.state = s
                self._rngs[i] = r
        c = st["counters"]
        self.evaluations, self.env_steps = int(c["evaluations"]), int(c["env_steps"])
        self.episodes, self.successes = int(c["episodes"]), int(c["successes"])
        self._reset_seeds()


# ----------------------------------------------------------------------------------------
# Configuration
# ----------------------------------------------------------------------------------------
_PAPER_T = {"matsumoto": 20_000_000, "carlike": 80_000_000, "panda-pole": 20_000_000}
#: Measured on this 2-core machine (shared with other jobs, 1 torch thread), PPO with the
#: paper's settings on Matsumoto: 0.9-1.0k steps/s with SB3's single environment
#: (DummyVecEnv over GeodesicEnv, n_steps 2048), 3.6-3.8k with 16 batched copies, no
#: better with 32 (PPO's 160 minibatch updates per rollout dominate); car-like 0.7k vs
#: 3.3k, Panda 3.1k with 16. The rollout per update stays SB3's 2048 steps (16 x 128).
_DEFAULT_N_ENVS = 16
_PAPER_ROLLOUT = 2048


@dataclass
class SeqConfig(MetricConfig):
    """Every setting of one Seq run (saved as ``config.json``). PPO settings not listed are
    stable-baselines3's defaults (normalised advantages, orthogonal initialisation, log-std
    initialised at 0, no target KL, no value clipping)."""

    env: str = "matsumoto"
    """Registered metric name (``finsler.list_metrics()``)."""
    metric_params: dict[str, Any] | None = None
    """Parameters of the metric (``finsler.get_metric(env, **metric_params)``); None or {}
    = its defaults. Completed to the full parameter set when the config is built."""
    metric_class: str | None = None
    """``module:qualname`` of a metric class registered outside the toolkit (filled in
    automatically; re-imported when the run is loaded in another process)."""
    method: str = "seq"
    """Always ``seq``."""
    seed: int = 0
    """Seed of SB3 (global python/numpy/torch generators, network initialisation) and of
    the environments (copy ``i`` is seeded with ``seed + i``)."""
    timesteps: int = 20_000_000
    """Budget of ALL-INCLUSIVE evaluations of F or C made by the environments (3 per step,
    2 per reset candidate); paper: 2e7 (Matsumoto, Panda), 8e7 (car-like) env steps."""
    minutes: float | None = None
    """Optional wall-clock limit across resumes; training stops at whichever comes first."""
    device: str = "cpu"
    """``cpu`` or ``cuda`` (SB3's networks; the environments run on numpy)."""
    threads: int = 1
    """torch intra-op threads (1 keeps runs bit-reproducible and leaves cores free)."""
    depth: int | None = None
    """Episodes last at most ``2**depth`` steps (paper: n = 2**D_max); None = the task's."""
    eps: float | None = None
    """Step cost of eq. (57) and success threshold; None = the task's."""
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
    eval_every: int = 200_000
    """All-inclusive timesteps between evaluations on the validation pair set (checked
    after every rollout); each evaluation also writes the latest checkpoint."""
    eval_pairs: int = 100
    """Size of the validation set (``finsler.validation_pairs``) on which
    ``checkpoint_best`` is chosen."""

    def __post_init__(self) -> None:
        self._check_types()
        self.hidden = tuple(int(h) for h in self.hidden)
        self.validate()

    def validate(self) -> None:
        """Raise :class:`finsler.InputError` naming the first impossible field."""
        self._check_env_and_device()
        if self.method != "seq":
            raise InputError(f"method must be 'seq' for a SeqConfig, got {self.method!r}")
        for name in ("timesteps", "threads", "batch_size", "n_envs", "n_steps", "n_epochs",
                     "eval_every", "eval_pairs"):
            v = getattr(self, name)
            if v < 1:
                raise InputError(f"{name} must be a positive integer, got {v!r}")
        if self.seed < 0:
            raise InputError(f"seed must be a non-negative integer, got {self.seed!r}")
        if self.minutes is not None and not (0 < self.minutes < math.inf):
            raise InputError(f"minutes must be positive and finite, got {self.minutes!r}")
        if self.depth is not None and self.depth < 1:
            raise InputError(f"depth must be a positive integer, got {self.depth!r}")
        if self.eps is not None and not (0 < self.eps < math.inf):
            raise InputError(f"eps must be positive and finite, got {self.eps!r}")
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
    rollout); ``overrides`` replace fields (unknown ones raise :class:`InputError`)."""
    ensure_registered(env, overrides.get("metric_class"))
    settings: dict[str, Any] = {"env": env, "timesteps": _PAPER_T.get(env, 20_000_000)}
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


def _config_json(cfg: SeqConfig) -> str:
    import gymnasium as gym
    import stable_baselines3 as sb3

    doc = {
        "config": cfg.to_dict(),
        "metric": metric_info(cfg),
        "task": {"depth": cfg.max_depth, "eps": cfg.eval_eps, "segments": 2**cfg.max_depth},
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
    return json.dumps(doc, indent=2)


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
            v = act(_obs(p[active], g[active]))
            q, moved, _ = _move(metric, eps, p[active], v)
            p[active] = q
            mv = active[moved]
            if mv.size:
                hit = np.asarray(metric.cost(p[mv], g[mv])) < eps
                reached_at[mv[hit]] = j
        pts[:, j] = p
    return pts, reached_at


@dataclass
class SeqEvalResult(EvalResult):
    """:class:`learn.policy.EvalResult` of Seq paths, plus the paper's episode success."""

    reached: np.ndarray = dataclasses.field(repr=False)
    """(K,) bool: ``C(p_j, g) < eps`` for some ``j <= 2**D`` (the paper's success for Seq,
    as in the authors' evaluation code)."""
    steps: np.ndarray = dataclasses.field(repr=False)
    """(K,) int: steps taken until reaching (``2**D`` if never reached)."""
    strict_success: np.ndarray = dataclasses.field(repr=False)
    """(K,) bool: :func:`learn.policy.evaluate_paths`' test without any tolerance."""

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
      :func:`learn.policy.evaluate_paths`' ``C <= eps`` would fail about half of the steps
      by rounding alone. The tolerance (1e-9 relative, 10^7 times the rounding, far below
      any change of the path) accepts exactly those; a step whose projection into the
      domain really raised its cost above eps still fails. The last segment is ``< eps``
      by the reach test, padding segments cost 0.
    * ``strict_success``: ``evaluate_paths``' test with no tolerance (shows the rounding).
    * ``reached``: the paper's/authors' success for Seq: ``C(p_j, g) < eps`` within the
      ``n`` steps of an episode (one more step than fits in n segments; no segment test).
    """
    if not isinstance(depth, (int, np.integer)) or isinstance(depth, bool) or depth < 0:
        raise InputError(f"depth must be a non-negative integer, got {depth!r}")
    if not (np.isfinite(eps) and eps > 0):
        raise InputError(f"eps must be positive and finite, got {eps!r}")
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
    )
    return res, paths


# ----------------------------------------------------------------------------------------
# Loaded policies
# ----------------------------------------------------------------------------------------
def _build_policy(cfg: SeqConfig, device: str = "cpu") -> Any:
    """An SB3 ``ActorCriticPolicy`` exactly as ``PPO("MlpPolicy", ...)`` builds it for
    ``cfg`` (untrained)."""
    from stable_baselines3.common.policies import ActorCriticPolicy

    obs, act = _spaces(cfg.metric)
    lr = cfg.lr
    return ActorCriticPolicy(obs, act, lambda _: lr, **_policy_kwargs(cfg)).to(
        resolve_device(device))


def _policy_kwargs(cfg: SeqConfig) -> dict[str, Any]:
    act = torch.nn.Tanh if cfg.activation == "tanh" else torch.nn.ReLU
    return {"net_arch": {"pi": list(cfg.hidden), "vf": list(cfg.hidden)}, "activation_fn": act}


class SeqPolicy:
    """A trained Seq policy (deterministic mean actions) for one metric; generates paths
    like :class:`learn.policy.Policy`."""

    def __init__(self, policy: Any, config: SeqConfig, source: str = "",
                 checkpoint: str = "") -> None:
        self.policy = policy
        self.policy.set_training_mode(False)
        self.config = config
        self.metric = config.metric
        self.depth = config.max_depth
        self.eps = config.eval_eps
        self.source = source
        self.checkpoint = checkpoint
        """File the weights came from (``checkpoint_best.pt`` or ``checkpoint_latest.pt``)."""

    def __repr__(self) -> str:
        return f"SeqPolicy(env={self.metric.name!r}, depth={self.depth}, source={self.source!r})"

    def _depth(self, depth: int | None) -> int:
        d = self.depth if depth is None else depth
        if not isinstance(d, (int, np.integer)) or isinstance(d, bool) or d < 0:
            raise InputError(f"depth must be a non-negative integer, got {depth!r}")
        return int(d)

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """Paths ``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)`` float64 (D = ``depth`` or the
        task's): the deterministic walk ``p_0..p_j`` until ``C(p_j, g) < eps`` (at most
        ``2**D - 1`` steps fit), then ``g`` repeated; a pair that does not get there
        within that many steps gets ``p_0..p_{n-1}, g`` (its last segment shows how far
        it was). Starts are ``p_0``, goals the last point."""
        d = self._depth(depth)
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
        success threshold. See :func:`evaluate_seq` for how success relates to
        :func:`learn.policy.evaluate_paths`."""
        p = finsler.default_pairs(self.metric) if pairs is None else check_pairs(
            self.metric, pairs)
        e = self.eps if eps is None else eps
        res, _ = evaluate_seq(_policy_fn(self.policy), self.metric, p, e, self._depth(depth))
        return res


def load_seq_policy(run_dir: str | Path, checkpoint: str = "best",
                    device: str = "cpu", env: str | None = None,
                    metric_params: dict[str, Any] | None = None) -> SeqPolicy:
    """Load the Seq policy of a run directory: ``checkpoint`` ``best`` (best validation
    success; falls back to the latest) or ``latest``; ``env`` / ``metric_params``, if
    given, must be the run's (:func:`learn.config.check_run_metric`)."""
    path = Path(run_dir)
    if not path.is_dir():
        raise InputError(f"run directory {str(run_dir)!r} does not exist")
    if checkpoint not in ("best", "latest"):
        raise InputError(f"checkpoint must be 'best' or 'latest', got {checkpoint!r}")
    doc = read_json(path / CONFIG_FILE)
    if not isinstance(doc.get("config"), dict):
        raise CorruptFileError(f"{path / CONFIG_FILE} has no 'config' section")
    if doc["config"].get("method") != "seq":
        raise InputError(f"{path} is not a Seq run (method {doc['config'].get('method')!r})")
    cfg = SeqConfig.from_dict(doc["config"])
    check_run_metric(cfg, f"policy {path}", env, metric_params)
    order = (BEST_FILE, LATEST_FILE) if checkpoint == "best" else (LATEST_FILE,)
    for name in order:
        if (path / name).is_file():
            ckpt = load_checkpoint(path / name)
            break
    else:
        raise InputError(f"run directory {path} holds no checkpoint ({', '.join(order)})")
    policy = _build_policy(cfg, device)
    try:
        policy.load_state_dict(ckpt["policy"])
    except (KeyError, RuntimeError) as err:
        raise CorruptFileError(f"checkpoint in {path} does not match its config: {err}") from err
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


class SeqTrainer:
    """PPO (stable-baselines3) on :class:`GeodesicVecEnv` into a run directory.

    One iteration = one SB3 rollout of ``n_envs * n_steps`` steps and its PPO update
    (``model.learn`` for exactly one rollout, ``reset_num_timesteps=False``: SB3's own
    loop, cut into rollouts so that budgets, evaluations and checkpoints fall between
    rollouts). The learning rate and clip range are constant (the paper's settings), so
    this is the same computation as one long ``learn`` call.
    """

    def __init__(self, cfg: SeqConfig, run_dir: str | Path, resume: bool = False,
                 progress: bool = True) -> None:
        from stable_baselines3 import PPO
        from stable_baselines3.common.logger import Logger

        if not isinstance(cfg, SeqConfig):
            raise InputError(f"train_seq needs a SeqConfig, got {type(cfg).__name__}")
        self.run_dir = check_run_dir(Path(run_dir), resume)
        self.progress = progress
        if resume:
            cfg = self._resume_config(cfg)
        self.cfg = cfg
        self.device = resolve_device(cfg.device)
        torch.set_num_threads(cfg.threads)
        self.metric = cfg.metric
        self.eval_pairs = finsler.validation_pairs(self.metric, cfg.eval_pairs)
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
        self.iteration = 0
        self.next_eval = 0
        self.wall_before = 0.0
        self.best: dict[str, float] = {"success_rate": -1.0, "mean_max_segment_cost": math.inf}
        self.history: list[dict[str, Any]] = []
        self._ep_mark = (0, 0)  # (episodes, successes) at the last metrics row
        if resume:
            if not (self.run_dir / LATEST_FILE).is_file():
                raise InputError(
                    f"cannot resume: {self.run_dir / LATEST_FILE} is missing (the run's "
                    "progress cannot be restored; nothing was changed). Start a new run "
                    "with another --out")
            self._load_state(load_checkpoint(self.run_dir / LATEST_FILE))
        else:
            # the first reset, as SB3's first ``learn`` would do it (seeds seed + i)
            self.model._last_obs = self.venv.reset()
            self.model._last_episode_starts = np.ones(cfg.n_envs, dtype=bool)
            self.run_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.run_dir / CONFIG_FILE, _config_json(cfg))

    # -- counters -------------------------------------------------------------------------
    @property
    def timesteps(self) -> int:
        """All-inclusive evaluations of F or C during training."""
        return self.venv.evaluations

    @property
    def timesteps_paper(self) -> int:
        """Environment steps (the paper's count)."""
        return self.venv.env_steps

    # -- resume ---------------------------------------------------------------------------
    def _resume_config(self, cfg: SeqConfig) -> SeqConfig:
        doc = read_json(self.run_dir / CONFIG_FILE)
        if not isinstance(doc.get("config"), dict):
            raise CorruptFileError(f"{self.run_dir / CONFIG_FILE} has no 'config' section")
        saved = SeqConfig.from_dict(doc["config"])
        if cfg.env != saved.env:
            raise InputError(f"cannot resume: run {self.run_dir} trains {saved.env!r}, "
                             f"not {cfg.env!r}")
        free = {"minutes", "device", "eval_pairs"}
        new, old = cfg.to_dict(), saved.to_dict()
        changed = [k for k in old if k not in free and new[k] != old[k]]
        if changed:
            raise InputError("cannot resume with different settings: " + ", ".join(
                f"{k} ({old[k]!r} in the run, {new[k]!r} given)" for k in changed))
        return saved.replace(minutes=cfg.minutes, device=cfg.device,
                             eval_pairs=cfg.eval_pairs)

    def _state(self) -> dict[str, Any]:
        m = self.model
        np_state = np.random.get_state(legacy=False)  # noqa: NPY002 (SB3's generator)
        return {
            "format": "learn-checkpoint-v1",
            "config": self.cfg.to_dict(),
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
            "counters": {
                "iteration": self.iteration,
                "timesteps": self.timesteps,
                "timesteps_paper": self.timesteps_paper,
                "timesteps_derivative": 0,
                "next_eval": self.next_eval,
                "wall_seconds": self._wall(),
                "episodes_mark": list(self._ep_mark),
            },
            "best": dict(self.best),
            "history": [dict(r) for r in self.history],
        }

    def _load_state(self, st: dict[str, Any]) -> None:
        m = self.model
        try:
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
            self.iteration = int(c["iteration"])
            self.next_eval = int(c["next_eval"])
            self.wall_before = float(c["wall_seconds"])
            self._ep_mark = (int(c["episodes_mark"][0]), int(c["episodes_mark"][1]))
            self.best = dict(st["best"])
        except (KeyError, RuntimeError, TypeError, ValueError, IndexError) as err:
            raise CorruptFileError(
                f"checkpoint {self.run_dir / LATEST_FILE} does not match the run: {err}"
            ) from err
        self.history = restore_history(self.run_dir, st, self.iteration)

    # -- one rollout + update -------------------------------------------------------------
    def train_rollout(self) -> None:
        """Collect one rollout of ``n_envs * n_steps`` steps and run PPO's update on it."""
        self.model.learn(total_timesteps=self.cfg.n_envs * self.cfg.n_steps,
                         reset_num_timesteps=False, log_interval=None, progress_bar=False)
        self.iteration += 1

    # -- evaluation, logging, checkpoints -------------------------------------------------
    def evaluate(self, pairs: np.ndarray | None = None) -> SeqEvalResult:
        """Deterministic policy on the validation set (all pairs at once)."""
        p = self.eval_pairs if pairs is None else pairs
        res, _ = evaluate_seq(_policy_fn(self.model.policy), self.metric, p,
                              self.cfg.eval_eps, self.cfg.max_depth)
        self.model.policy.set_training_mode(False)
        return res

    def _wall(self) -> float:
        return self.wall_before + (time.perf_counter() - self._t0)

    def _log_and_checkpoint(self) -> dict[str, Any]:
        ev = self.evaluate()
        wall = self._wall()
        logged = self.model.logger.name_to_value if self.iteration > 0 else {}
        eps_done = self.venv.episodes - self._ep_mark[0]
        succ = self.venv.successes - self._ep_mark[1]
        self._ep_mark = (self.venv.episodes, self.venv.successes)
        row: dict[str, Any] = {
            "iteration": self.iteration,
            "timesteps": self.timesteps,
            "timesteps_paper": self.timesteps_paper,
            "timesteps_derivative": 0,
            "wall_seconds": round(wall, 3),
            "success_rate": ev.success_rate,
            "mean_length": round(ev.mean_length, 8),
            "mean_max_segment_cost": round(ev.mean_max_segment_cost, 8),
            "reached_rate": ev.reached_rate,
            "strict_success_rate": ev.strict_success_rate,
            "mean_steps": float(np.mean(ev.steps)),
            "train_episodes": eps_done,
            "train_success_rate": round(succ / eps_done, 6) if eps_done else float("nan"),
        }
        for col, key in _TRAIN_KEYS.items():
            row[col] = float(logged[key]) if key in logged else float("nan")
        row["lr"] = self.cfg.lr
        row["evaluations_per_second"] = round(self.timesteps / max(wall, 1e-9), 1)
        row["steps_per_second"] = round(self.timesteps_paper / max(wall, 1e-9), 1)
        self.history.append(row)
        write_metrics(self.run_dir / METRICS_FILE, self.history)
        key = (ev.success_rate, -ev.mean_max_segment_cost)
        if key > (self.best["success_rate"], -self.best["mean_max_segment_cost"]):
            self.best = {
                "success_rate": ev.success_rate,
                "mean_max_segment_cost": ev.mean_max_segment_cost,
                "mean_length": ev.mean_length,
                "reached_rate": ev.reached_rate,
                "timesteps": self.timesteps,
                "timesteps_paper": self.timesteps_paper,
                "iteration": self.iteration,
                "wall_seconds": wall,
            }
            save_checkpoint(self.run_dir / BEST_FILE, {
                "format": "learn-checkpoint-v1",
                "config": self.cfg.to_dict(),
                "policy": self.model.policy.state_dict(),
                "eval": dict(self.best),
            })
        save_checkpoint(self.run_dir / LATEST_FILE, self._state())
        return row

    def run(self) -> TrainResult:
        """Train until ``timesteps`` (all-inclusive) or ``minutes`` is spent."""
        from tqdm.auto import tqdm

        cfg = self.cfg
        self._t0 = time.perf_counter()
        (self.run_dir / RESULT_FILE).unlink(missing_ok=True)
        bar = tqdm(total=cfg.timesteps, initial=min(self.timesteps, cfg.timesteps), unit="C",
                   unit_scale=True, disable=not self.progress, desc=f"seq {cfg.env}",
                   dynamic_ncols=True)
        if self.iteration == 0 and not self.history:
            self._log_and_checkpoint()
            self.next_eval = cfg.eval_every
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
                    before = self.timesteps
                    self.train_rollout()
                    bar.update(min(self.timesteps, cfg.timesteps) - min(before, cfg.timesteps))
                    if self.timesteps >= self.next_eval:
                        while self.next_eval <= self.timesteps:
                            self.next_eval += cfg.eval_every
                        row = self._log_and_checkpoint()
                        last_logged = self.iteration
                        bar.set_postfix(success=f"{row['success_rate']:.2f}",
                                        steps_s=f"{row['steps_per_second']:.0f}")
                if self.iteration != last_logged:
                    self._log_and_checkpoint()
            finally:
                bar.close()
        return finish_run(self.run_dir, self.history, self.best, stopped_by,
                          self.timesteps, self.iteration)


def train_seq(cfg: SeqConfig, out: str | Path, resume: bool = False,
              progress: bool = True) -> TrainResult:
    """Train Seq (PPO, appendix B.2) with ``cfg`` into run directory ``out``.

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
    return SeqTrainer(cfg, out, resume=resume, progress=progress).run()
