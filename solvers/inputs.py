"""Input checks shared by the solvers (the lowest solver module: imports only finsler).

The public functions (``solve_geodesic``, ``solve_batch``, ``distance``, ``exp_map``,
``log_map``, ``certify``, ``refine_minmax``) check their input here once; what they call
below takes the checked objects and does not check again."""

from __future__ import annotations

from typing import Any

import numpy as np

from finsler.domains import as_real, describe_value, is_torch
from finsler.errors import InputError, short
from finsler.metrics.base import Metric
from finsler.registry import get_metric

__all__ = [
    "SHORT_PAIR",
    "as_metric",
    "check_initial",
    "check_pairs",
    "check_point",
    "check_segments",
    "domain_scale",
    "is_short_pair",
]

#: Pairs with ``max |g - s| <= SHORT_PAIR * domain size`` are solved as straight segments.
SHORT_PAIR = 1e-7


def domain_scale(m: Metric) -> float:
    """Largest side of the domain's bounding box (1 if unbounded)."""
    lo, hi = m.domain.bounds()
    span = np.asarray(hi, float) - np.asarray(lo, float)
    span = span[np.isfinite(span)]
    return float(np.max(span)) if span.size else 1.0


def is_short_pair(m: Metric, s: np.ndarray, g: np.ndarray) -> bool:
    """True if start and goal are closer than ``SHORT_PAIR`` times the domain size."""
    return bool(np.max(np.abs(g - s)) <= SHORT_PAIR * domain_scale(m))


def as_metric(metric: Metric | str) -> Metric:
    """A metric object, or the registered metric of that name, whose ``F`` passed the first
    look of `Metric.check_values` (finite and positive at a few points of the domain)."""
    if isinstance(metric, Metric):
        metric.check_values()
        return metric
    if isinstance(metric, str):
        m = get_metric(metric)
        m.check_values()
        return m
    raise InputError(f"metric must be a finsler.Metric or a registered name, got "
                     f"{describe_value(metric)}")


def check_segments(metric: Metric, segments: int | None) -> int:
    """Validate the number of segments (``None`` -> the task's ``2**D``); ``n >= 2``."""
    if segments is None:
        return metric.task.segments
    if isinstance(segments, bool) or not isinstance(segments, (int, np.integer)):
        raise InputError(f"segments must be an integer >= 2, got {describe_value(segments)}")
    if segments < 2:
        raise InputError(f"segments must be >= 2 (interior points to optimise), got {segments}")
    if segments > 1 << 16:
        raise InputError(f"segments = {segments} is too large (max 65536)")
    return int(segments)


def check_point(metric: Metric, x: Any, name: str) -> np.ndarray:
    """One point ``(dim,)`` (or ``(1, dim)``), finite and in the domain -> float64 ``(dim,)``."""
    arr = as_real(x, name, f"a point: a real numeric array of shape ({metric.dim},)")
    if arr.ndim == 2 and arr.shape[0] != 1:
        raise InputError(f"{name} must be a single point of shape ({metric.dim},), got "
                         f"{tuple(arr.shape)}")
    return metric.domain.check(arr, name)[0].astype(np.float64)


def check_pairs(metric: Metric, pairs: Any,
                names: tuple[str, str] = ("pairs[:, 0] (starts)", "pairs[:, 1] (goals)")
                ) -> np.ndarray:
    """Validate start/goal pairs ``(K, 2, dim)``: shape, finiteness, domain membership;
    ``names``: how error messages name the starts and the goals (a command line names its
    options)."""
    arr = as_real(pairs, "pairs", f"a real numeric array of shape (K, 2, {metric.dim})")
    if is_torch(arr):
        arr = arr.detach().cpu().numpy().astype(np.float64)
    if arr.ndim != 3 or arr.shape[1] != 2 or arr.shape[2] != metric.dim or arr.shape[0] < 1:
        raise InputError(
            f"pairs must have shape (K, 2, {metric.dim}) with K >= 1 for metric "
            f"{short(metric.name, 80)!r}, got {arr.shape}"
        )
    metric.domain.check(arr[:, 0], names[0])
    metric.domain.check(arr[:, 1], names[1])
    return arr


#: Most caller-given initial paths of one solve (each is solved as a seed).
MAX_INITIAL_PATHS = 256


def check_initial(initial: Any) -> tuple[Any, ...]:
    """The ``initial`` paths of one solve as a tuple: a list or tuple of paths ``(m+1,
    dim)``, or an array ``(P, m+1, dim)`` of ``P`` paths (each path's shape and values are
    checked by the solve, which knows its ends); anything else is an `InputError`."""
    if isinstance(initial, np.ndarray) or is_torch(initial):
        if initial.ndim != 3:
            raise InputError(f"initial must be a list of paths (m+1, dim) or an array (P, m+1, "
                             f"dim), got {describe_value(initial)}")
        initial = list(initial)
    if not isinstance(initial, (list, tuple)):
        raise InputError(f"initial must be a list of paths (m+1, dim), got "
                         f"{describe_value(initial)}")
    if len(initial) > MAX_INITIAL_PATHS:
        raise InputError(f"initial holds {len(initial)} paths, above the limit of "
                         f"{MAX_INITIAL_PATHS}")
    return tuple(initial)
