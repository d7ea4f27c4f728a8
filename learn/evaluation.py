"""The section 5.1 evaluation every learning method's paths are judged by.

`evaluate_paths` scores paths ``(K, n + 1, dim)`` on a pair set: a path succeeds when every
segment cost ``C(p_i, p_{i+1})`` is at most ``eps``, all in float64; `EvalResult` holds the
rates and the per-pair values. `check_pairs` checks a pair set ``(K, 2, dim)`` once, for
every method's ``evaluate``.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import finsler
from finsler.domains import as_real, is_torch
from finsler.errors import InputError
from finsler.infra.limits import check_number
from finsler.status import EvalStatus, Result, json_ready

__all__ = ["EvalResult", "check_pairs", "evaluate_paths"]


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
