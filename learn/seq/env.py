"""The gymnasium environment of the Seq baseline (section 5.2, appendix B.2): a
goal-conditioned walk of eqs. (57) and (14) on any metric.

The agent walks from a start ``s`` to a goal ``g`` in steps of local cost ``eps``:

* observation ``(p, g)`` (``2 * dim``), action a direction ``v`` (``dim``, in ``[-1, 1]``);
* next point, eq. (57): ``q = p + eps / F(p, v) * v``, projected into the domain (the
  coordinates are the chart, so ``df`` is the identity);
* reward, eq. (14): ``R = F(g, g - p) - F(g, g - q) - eps``; a zero action leaves ``p``
  where it is and gives ``R = -100``;
* the episode terminates (success) when ``C(q, g) < eps`` and is truncated after
  ``n = 2**D`` steps (D: the task's depth).

`GeodesicEnv` is that environment (gymnasium API); `GeodesicVecEnv` steps
``n_envs`` copies at once with one vectorised evaluation of ``F`` per quantity (a
stable-baselines3 ``VecEnv`` with exactly the transitions of ``DummyVecEnv`` over
`GeodesicEnv`). `move` (eq. 57) and `observation` also serve the
deterministic rollouts of `learn.seq.trainer`.

**Counting.** Every evaluation of ``F`` or ``C`` the environment makes is counted
(`GeodesicEnv.evaluations`), whatever for: per step with a non-zero action exactly 3
(``F(p, v)`` of eq. (57), ``F(g, g - q)`` of eq. (14) and ``C(q, g)`` of the termination
test; ``F(g, g - p)`` is carried over from the previous step), 0 for a zero action
(nothing changes), and 2 per sampled start/goal candidate at a reset (``F(g, g - s)`` and
``C(s, g)``; 1 for a reset to given points). `GeodesicEnv.env_steps` counts steps
(the paper's count).
"""

from __future__ import annotations

import math
from typing import Any

import gymnasium
import numpy as np
import torch
from gymnasium import spaces
from gymnasium.utils import seeding
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

import finsler
from finsler.errors import InputError

__all__ = [
    "TIME_LIMITS",
    "ZERO_ACTION_REWARD",
    "GeodesicEnv",
    "GeodesicVecEnv",
    "env_spaces",
    "move",
    "observation",
]

#: Reward of a zero action (appendix B.2); the point does not move.
ZERO_ACTION_REWARD = -100.0
TIME_LIMITS = ("truncate", "terminate")
"""How the step limit may end an episode (see `SeqConfig`.time_limit)."""
_MAX_RESAMPLE_ROUNDS = 1000


# ----------------------------------------------------------------------------------------
# The transition of eqs. (57) and (14), batch-first, float64
# ----------------------------------------------------------------------------------------
def _metric_of(metric: finsler.Metric | str) -> finsler.Metric:
    return metric if isinstance(metric, finsler.Metric) else finsler.get_metric(metric)


def move(metric: finsler.Metric, eps: float, p: np.ndarray,
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
    q, moved, n_eval = move(metric, eps, p, v)
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


def env_spaces(metric: finsler.Metric) -> tuple[spaces.Box, spaces.Box]:
    """Observation box ``(p, g)`` from the domain's bounds and action box ``[-1, 1]**dim``
    (float32, as SB3's networks use)."""
    lo, hi = metric.domain.bounds()
    lo2 = np.concatenate([lo, lo]).astype(np.float32)
    hi2 = np.concatenate([hi, hi]).astype(np.float32)
    obs = spaces.Box(lo2, hi2, dtype=np.float32)
    act = spaces.Box(-np.ones(metric.dim, np.float32), np.ones(metric.dim, np.float32),
                     dtype=np.float32)
    return obs, act


def observation(p: np.ndarray, g: np.ndarray) -> np.ndarray:
    return np.concatenate([p, g], axis=-1).astype(np.float32)


def _check_action(a: Any, n: int, dim: int) -> np.ndarray:
    """Actions as float64 ``(n, dim)``; `InputError` for a wrong size or NaN/inf."""
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

    Parameters: ``metric`` (a [`finsler.Metric`][finsler.Metric] or a registered name), ``eps``
    (step cost and success threshold; default the task's), ``depth`` (the episode lasts at
    most ``2**depth`` steps; default the task's), ``reject_solved`` (redraw start/goal
    pairs with ``C(s, g) < eps``, as the authors' code does).

    ``reset(seed=..., options={"start": s, "goal": g})`` starts from given points (no
    redraw). The state is float64; observations are float32 ``(2 * dim,)``. Counters:
    `evaluations` (every evaluation of F or C, see the module docstring) and
    `env_steps` (steps taken, the paper's count). ``info["is_success"]`` marks the
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
        self.observation_space, self.action_space = env_spaces(self.metric)
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
        return observation(self._p, self._g)[0], {"evaluations": n_eval}

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
        return observation(self._p, self._g)[0], float(reward[0]), terminated, truncated, info


class GeodesicVecEnv(VecEnv):
    """``n_envs`` copies of `GeodesicEnv` stepped together: one vectorised call of
    ``F`` per quantity for all copies instead of one per copy.

    Same transitions, rewards, infos and random streams as
    ``DummyVecEnv([lambda: GeodesicEnv(...)] * n_envs)``: copy ``i`` has its own
    generator, seeded with ``seed + i`` at the first `reset` after `seed`;
    finished copies are reset automatically and their last observation is in
    ``info["terminal_observation"]`` (SB3's convention). Rewards are float32 as in
    ``DummyVecEnv``. Counters: `evaluations` (all copies, all-inclusive),
    `env_steps` (steps of all copies), `episodes` and `successes`
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
        return observation(self._p, self._g)

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
        obs = observation(self._p, self._g)
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
            obs[done_rows] = observation(self._p[done_rows], self._g[done_rows])
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
