"""Trained midpoint policies: loading, path generation and the section 5.1 evaluation.

``load_policy(run_dir_or_env)`` accepts a run directory of any learning method (its
loader is found in `learn.registry`) or the name of an environment with a shipped
policy (``matsumoto``, ``carlike``, ``panda-pole``); a midpoint [`Policy`][learn.policy.Policy]
generates paths by ``D`` batched actor calls.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import torch

import finsler
from finsler.domains import as_real, is_torch
from finsler.errors import InputError, short
from finsler.infra.files import check_path_text
from finsler.infra.limits import check_number
from finsler.status import EvalStatus, Result, json_ready
from learn.base import LoadedPolicy
from learn.config import METHODS, TrainConfig
from learn.loop import load_run, load_weights, read_config_section
from learn.networks import Actor, Critic, predictor, resolve_device
from learn.registry import method_of_run
from learn.search import SearchResult, SearchSpec, search_paths
from learn.storage import BEST_FILE, CONFIG_FILE, LATEST_FILE, POLICY_FILE, load_checkpoint
from learn.tree import build_tree, level_pairs, mc_targets

__all__ = [
    "EvalResult",
    "Policy",
    "build_actor",
    "check_pairs",
    "evaluate_paths",
    "evaluate_policy",
    "export_policy",
    "load_midpoint_policy",
    "load_policy",
    "shipped_policies",
]


def build_actor(cfg: TrainConfig, metric: finsler.Metric | None = None) -> Actor:
    """The actor network described by ``cfg`` (untrained)."""
    return Actor(
        metric if metric is not None else cfg.metric,
        hidden=cfg.hidden,
        activation=cfg.activation,
        normalize_inputs=cfg.normalize_inputs,
        residual=cfg.actor_residual,
        relative=cfg.actor_relative,
        log_std_min=cfg.log_std_min,
        log_std_max=cfg.log_std_max,
        init_log_std=cfg.init_log_std,
        explore_std=cfg.explore_std,
        heads=cfg.actor_heads,
    )


def build_critic(cfg: TrainConfig, metric: finsler.Metric | None = None) -> Critic:
    """The critic network described by ``cfg`` (untrained): ``critic_hidden`` (else the
    actor's ``hidden``), the transform and the symmetry of the run."""
    return Critic(
        metric if metric is not None else cfg.metric,
        hidden=cfg.critic_hidden or cfg.hidden,
        activation=cfg.activation,
        normalize_inputs=cfg.normalize_inputs,
        transform=cfg.critic_transform,
        symmetric=cfg.symmetric_critic,
    )


def generate_paths(
    actor: Actor, metric: finsler.Metric, starts: torch.Tensor, goals: torch.Tensor, depth: int
) -> torch.Tensor:
    """Deterministic (mean) midpoint trees, float64: ``(K, dim)`` x2 -> ``(K, 2**D+1, dim)``.

    The actor runs in float32; midpoints are cast to float64 and projected into the domain.
    """
    with torch.no_grad():
        return build_tree(starts.to(torch.float64), goals.to(torch.float64), depth,
                          predictor(actor, metric))


@dataclass
class EvalResult(Result):
    """Section 5.1 evaluation of paths on a pair set (a `finsler.status.Result`:
    ``status`` is an `finsler.status.EvalStatus`, ``success`` when every path
    passed, so ``strict()`` raises unless the success rate is 1)."""

    success_rate: float
    """Fraction of pairs whose every segment cost C(p_i, p_{i+1}) <= eps."""
    mean_length: float
    """Mean over pairs of the path length sum_i C(p_i, p_{i+1})."""
    mean_max_segment_cost: float
    """Mean over pairs of max_i C(p_i, p_{i+1})."""
    eps: float
    depth: int
    success: np.ndarray = field(repr=False)
    """(K,) bool."""
    length: np.ndarray = field(repr=False)
    """(K,) float64."""
    max_segment_cost: np.ndarray = field(repr=False)
    """(K,) float64."""
    wall_time: float = field(default=0.0, kw_only=True)
    """Seconds the evaluation took."""

    @property
    def status(self) -> EvalStatus:  # type: ignore[override]
        """``not_finite`` if a path's length is not finite, else ``success`` if every path
        passed, else ``partial``."""
        if not np.all(np.isfinite(np.asarray(self.length, dtype=np.float64))):
            return EvalStatus.NOT_FINITE
        return EvalStatus.SUCCESS if bool(np.all(self.success)) else EvalStatus.PARTIAL

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict with keys success_rate, mean_length, mean_max_segment_cost,
        eps, depth, status, converged, wall_time and per_pair (list of success, length,
        max_segment_cost); non-finite numbers are ``None``."""
        return json_ready({
            "success_rate": float(self.success_rate),
            "mean_length": float(self.mean_length),
            "mean_max_segment_cost": float(self.mean_max_segment_cost),
            "eps": float(self.eps),
            "depth": int(self.depth),
            "per_pair": [
                {"success": bool(s), "length": float(length), "max_segment_cost": float(c)}
                for s, length, c in zip(self.success, self.length, self.max_segment_cost)
            ],
            "status": self.status.label,
            "converged": self.converged,
            "wall_time": float(self.wall_time),
        })


def evaluate_paths(metric: finsler.Metric, paths: np.ndarray, eps: float) -> EvalResult:
    """Success (every segment cost <= eps), length and max segment cost of paths
    ``(K, n + 1, dim)``, all in float64."""
    check_number(eps, "eps", 0.0, low_open=True)
    t0 = time.perf_counter()
    paths = as_real(paths, "paths", f"a real numeric array of shape (K, n+1, {metric.dim})")
    costs = metric.path_costs(paths)
    mx = costs.max(axis=1)
    length = costs.sum(axis=1)
    ok = mx <= eps
    depth = (paths.shape[1] - 1).bit_length() - 1
    return EvalResult(
        success_rate=float(ok.mean()),
        mean_length=float(length.mean()),
        mean_max_segment_cost=float(mx.mean()),
        eps=float(eps),
        depth=depth,
        success=ok,
        length=length,
        max_segment_cost=mx,
        wall_time=time.perf_counter() - t0,
    )


def check_pairs(metric: finsler.Metric, pairs: Any) -> np.ndarray:
    """``pairs`` as float64 ``(K, 2, dim)``, checked: shape, K >= 1, finite, in the domain."""
    arr = as_real(pairs, "pairs", f"a real numeric array of shape (K, 2, {metric.dim})")
    if is_torch(arr):
        arr = arr.detach().cpu().numpy().astype(np.float64)
    if arr.ndim != 3 or arr.shape[1] != 2 or arr.shape[2] != metric.dim:
        raise InputError(
            f"pairs must have shape (K, 2, {metric.dim}) for {metric.name}, got {arr.shape}"
        )
    if arr.shape[0] < 1:
        raise InputError("pairs is empty")
    if not np.all(np.isfinite(arr)):
        raise InputError("pairs contain NaN or inf")
    metric.domain.check(arr[:, 0], "pair starts")
    metric.domain.check(arr[:, 1], "pair goals")
    return arr


class Policy(LoadedPolicy):
    """A trained midpoint policy (deterministic means) for one metric."""

    def __init__(self, actor: Actor, config: TrainConfig, source: str = "",
                 checkpoint: str = "") -> None:
        super().__init__(config, source, checkpoint)
        self.actor = actor.eval()

    def _points(self, x: Any, name: str) -> torch.Tensor:
        xn = self.metric.domain.check(x, name)
        return torch.as_tensor(xn, dtype=torch.float64)

    def _pair_points(self, starts: Any, goals: Any) -> tuple[torch.Tensor, torch.Tensor]:
        s = self._points(starts, "starts")
        g = self._points(goals, "goals")
        if s.shape != g.shape:
            raise InputError(f"starts and goals differ in shape: {tuple(s.shape)} vs "
                             f"{tuple(g.shape)}")
        return s, g

    def generate(self, starts: Any, goals: Any, depth: int | None = None) -> np.ndarray:
        """Paths by recursive midpoint insertion: ``(K, dim)`` x2 -> ``(K, 2**D + 1, dim)``
        float64 (D = ``depth`` or the task's depth). Endpoints are the given points."""
        d = self.check_depth(depth)
        s, g = self._pair_points(starts, goals)
        return generate_paths(self.actor, self.metric, s, g, int(d)).cpu().numpy()

    def search(self, starts: Any, goals: Any, spec: SearchSpec | None = None,
               depth: int | None = None, eps: float | None = None) -> SearchResult:
        """Paths by policy-guided route search (`learn.search`: candidate midpoints at
        the top levels chosen by the true cost of the actor's completed paths, polishing by
        the actor's midpoints, windows re-generated by the actor's trees, then segment costs
        equalized along the path; values of C only). Before equalizing never longer (sum C)
        than `generate`'s path, pair by pair; successful (every segment cost <=
        ``eps``, default the task's) wherever that path is. Returns the paths and the
        evaluations of C the search made."""
        d = self.check_depth(depth)
        s, g = self._pair_points(starts, goals)
        return search_paths(self.metric, predictor(self.actor, self.metric), s, g, d,
                            self.eps if eps is None else eps, spec)

    def midpoint(self, starts: Any, goals: Any) -> np.ndarray:
        """Predicted midpoints ``(K, dim)`` (the deterministic mean, projected)."""
        out = self.generate(starts, goals, depth=1)[:, 1]  # checks the points first
        return out[0] if np.ndim(starts) == 1 else out

    def evaluate(
        self, pairs: Any = None, eps: float | None = None, depth: int | None = None,
        search: SearchSpec | None = None,
    ) -> EvalResult:
        """Section 5.1 evaluation on ``pairs`` ``(K, 2, dim)`` (default: the environment's
        default evaluation set, ``finsler.default_pairs``) of the generated paths, or of the
        searched ones with ``search`` (`search`)."""
        p = finsler.default_pairs(self.metric) if pairs is None else check_pairs(
            self.metric, pairs)
        if search is not None:
            paths = self.search(p[:, 0], p[:, 1], search, depth=depth, eps=eps).paths
        else:
            paths = self.generate(p[:, 0], p[:, 1], depth=depth)
        return evaluate_paths(self.metric, paths, self.eps if eps is None else eps)


def evaluate_policy(
    policy: Policy, pairs: Any = None, eps: float | None = None, depth: int | None = None
) -> EvalResult:
    """Functional form of [`Policy.evaluate`][learn.policy.Policy.evaluate]."""
    return policy.evaluate(pairs, eps=eps, depth=depth)


def shipped_policies() -> list[str]:
    """Environments with a policy shipped inside the package."""
    root = resources.files("learn") / "policies"
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / POLICY_FILE).is_file())


def _shipped_dir(name: str) -> Path:
    return Path(str(resources.files("learn") / "policies" / name))


def load_midpoint_policy(run: str | Path, device: str = "cpu", checkpoint: str = "best",
                         env: str | None = None,
                         metric_params: dict[str, Any] | None = None) -> Policy:
    """The midpoint learner's loader (`load_policy` picks it from the registry for
    ``midpoint`` / ``inter`` / ``two-to-one`` runs and shipped policies): a run directory
    or, given an environment name, the policy shipped with the package."""
    path = Path(run)
    if not path.is_dir():
        if str(run) in shipped_policies():
            path = _shipped_dir(str(run))
        else:
            known = ", ".join(shipped_policies()) or "none"
            raise InputError(
                f"run directory {short(str(run), 80)!r} does not exist and is not the name "
                f"of a shipped policy (shipped: {known})"
            )
    path, cfg, ckpt, loaded = load_run(path, checkpoint, TrainConfig, METHODS, env,
                                       metric_params)
    actor = build_actor(cfg)
    load_weights(actor, ckpt.get("actor"), path)
    if device != "cpu":
        actor = actor.to(resolve_device(device))
    return Policy(actor, cfg, source=str(path), checkpoint=loaded)


def load_policy(run: str | Path, device: str = "cpu", checkpoint: str = "best",
                env: str | None = None, metric_params: dict[str, Any] | None = None) -> Any:
    """Load the policy of any learning method from a run directory (the method's loader,
    found in `learn.registry` by the run's ``method``), or, given an environment
    name, the midpoint policy shipped with the package. ``checkpoint``: ``best`` (best
    success on the validation set during training; falls back to the latest) or
    ``latest``; the policy's ``checkpoint`` attribute names the file actually loaded.
    With ``env``, the policy must belong to that environment; with ``metric_params``, to
    the metric with those parameters (the run's config records them; runs written before
    the field existed are on the defaults). A user metric's class is re-imported from the
    config's ``metric_class``, a user method's module from ``method_module``, if they are
    not registered.

    Raises `InputError` for a missing directory, an unknown name, an ``env`` or
    parameter mismatch, and `CorruptFileError` for unreadable files.
    """
    path = check_path_text(run, "run (a run directory or a shipped policy's name)")
    for name, value in (("checkpoint", checkpoint), ("device", device)):
        if not isinstance(value, str):
            raise InputError(f"{name} must be a str, got {type(value).__name__} "
                             f"{short(repr(value), 80)}")
    if env is not None and not isinstance(env, str):
        raise InputError(f"env must be a metric name (str) or None, got {type(env).__name__} "
                         f"{short(repr(env), 80)}")
    if metric_params is not None and not isinstance(metric_params, dict):
        raise InputError(f"metric_params must be a dict or None, got "
                         f"{type(metric_params).__name__} {short(repr(metric_params), 80)}")
    if path.is_dir():
        method = method_of_run(path, read_config_section(path))
        return method.load_policy(path, checkpoint=checkpoint, device=device, env=env,
                                  metric_params=metric_params)
    return load_midpoint_policy(run, device=device, checkpoint=checkpoint, env=env,
                                metric_params=metric_params)


def load_critic(run: str | Path, checkpoint: str = "best", device: str = "cpu") -> Critic:
    """The critic ``V(s, g)`` of a midpoint run's checkpoint (``best`` or ``latest``), in
    eval mode. Shipped policies and exported ones keep the actor only.

    Raises `InputError` for a missing directory or a checkpoint without a critic,
    and `CorruptFileError` for unreadable files.
    """
    path = Path(run)
    if not path.is_dir():
        raise InputError(f"run directory {str(run)!r} does not exist (a critic is kept in a "
                         "run's checkpoints only; shipped policies keep the actor)")
    path, cfg, ckpt, loaded = load_run(path, checkpoint, TrainConfig, METHODS, None, None)
    if ckpt.get("critic") is None:
        raise InputError(f"{path / loaded} holds no critic (an exported or shipped policy "
                         "keeps the actor only)")
    critic = build_critic(cfg)
    load_weights(critic, ckpt["critic"], path)
    return critic.to(resolve_device(device)).eval()


def critic_level_errors(metric: finsler.Metric, paths: Any,
                        value: Callable[[torch.Tensor, torch.Tensor], torch.Tensor]
                        ) -> list[np.ndarray]:
    """How far a critic is off the cost of a policy's own sub-paths, level by level: for
    paths ``(K, 2**D + 1, dim)`` (a midpoint tree's points in order), level ``l`` holds
    the ``2**l`` sub-pairs ``(p_i, p_{i + 2**(D-l)})`` of each path, and its entry is
    ``value(p_i, p_j) / (sum of C over the segments between them) - 1``, shape
    ``(K * 2**l,)``; levels ``0 .. D`` (level D: single segments, where the sub-path cost
    is one evaluation of C). ``value`` takes float64 tensors ``(N, dim)`` x2."""
    paths = np.asarray(paths, dtype=np.float64)
    n = paths.shape[1] - 1 if paths.ndim == 3 else 0
    if n < 1 or n & (n - 1):
        raise InputError(f"paths must have shape (K, 2**D + 1, dim), got {paths.shape}")
    costs = metric.path_costs(paths)
    if np.any(costs <= 0):
        raise InputError("a segment of zero cost has no relative error (repeated points)")
    pts = torch.as_tensor(paths)
    out = []
    for lev, true in enumerate(mc_targets(torch.tensor(costs))):  # sub-path costs
        a, b = level_pairs(pts, lev)
        with torch.no_grad():
            v = value(a.reshape(-1, metric.dim), b.reshape(-1, metric.dim))
        out.append(np.asarray(v.detach().cpu(), dtype=np.float64) / true.reshape(-1).numpy()
                   - 1.0)
    return out


def export_policy(run_dir: str | Path, dest: str | Path, checkpoint: str = "best") -> Path:
    """Copy a run's policy (actor weights only, float32), its ``config.json`` and its
    ``metrics.csv`` (the learning curve) into ``dest`` -- the layout of the shipped
    policies in ``learn/policies/<env>/``. Returns ``dest``."""
    from learn.storage import METRICS_FILE, atomic_write_bytes, save_checkpoint

    src = Path(run_dir)
    pol = load_midpoint_policy(src, checkpoint=checkpoint)
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    ck = load_checkpoint(src / (BEST_FILE if checkpoint == "best" and (src / BEST_FILE)
                                .is_file() else LATEST_FILE))
    save_checkpoint(dest / POLICY_FILE, {
        "format": "learn-checkpoint-v1",
        "config": pol.config.to_dict(),
        "actor": {k: v.detach().cpu().clone() for k, v in pol.actor.state_dict().items()},
        "eval": ck.get("eval", {}),
    })
    atomic_write_bytes(dest / CONFIG_FILE, (src / CONFIG_FILE).read_bytes())
    if (src / METRICS_FILE).is_file():
        atomic_write_bytes(dest / METRICS_FILE, (src / METRICS_FILE).read_bytes())
    return dest
