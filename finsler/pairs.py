"""Evaluation pair sets: fixed, deterministic samples of start/goal pairs."""

from __future__ import annotations

import numpy as np

from finsler.errors import InputError
from finsler.metric import Metric

__all__ = ["DEFAULT_EVAL_SEED", "default_pairs", "sample_pairs"]

#: Seed of every environment's default evaluation set (100 uniform pairs).
DEFAULT_EVAL_SEED = 20240531


def sample_pairs(metric: Metric, k: int, seed: int) -> np.ndarray:
    """``k`` start/goal pairs, both endpoints uniform on the domain -> ``(k, 2, dim)``.

    Deterministic for a given seed (numpy's PCG64 stream is stable across versions).
    """
    if not isinstance(k, (int, np.integer)) or k < 1:
        raise InputError(f"number of pairs must be a positive integer, got {k!r}")
    rng = np.random.default_rng(seed)
    pts = metric.domain.sample(2 * int(k), rng)
    return pts.reshape(int(k), 2, metric.dim)


def default_pairs(metric: Metric, k: int = 100) -> np.ndarray:
    """The environment's default evaluation set: ``k`` (100) uniform pairs, fixed seed."""
    return sample_pairs(metric, k, DEFAULT_EVAL_SEED)
