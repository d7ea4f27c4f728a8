"""Seq's paths: deterministic rollouts of the goal-conditioned walk, their section 5.1
evaluation (`evaluate_seq`, `SeqEvalResult`), and the loaded policy (`SeqPolicy`,
`load_seq_policy`)."""

from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from finsler.infra.limits import check_count, check_number
from learn.base import MAX_DEPTH, LoadedPolicy
from learn.evaluation import EvalResult, check_pairs
from learn.loop import load_run, load_weights, resolve_device
from learn.seq.config import SEGMENT_RTOL, SeqConfig
from learn.seq.env import env_spaces, move, observation

__all__ = [
    "SeqEvalResult",
    "SeqPolicy",
    "evaluate_seq",
    "load_seq_policy",
    "mean_actions",
    "policy_kwargs",
    "rollout",
]


def mean_actions(policy: Any) -> Any:
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
    return ActorCriticPolicy(obs, act, lambda _: lr, **policy_kwargs(cfg)).to(
        resolve_device(device))


def policy_kwargs(cfg: SeqConfig) -> dict[str, Any]:
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
        pts, reached_at = rollout(mean_actions(self.policy), self.metric, s, g, self.eps, n)
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
        res, _ = evaluate_seq(mean_actions(self.policy), self.metric, p, e, self.check_depth(depth))
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


