"""Evaluation pair sets: fixed, deterministic samples of start/goal pairs."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from finsler.domains import Domain, describe_value
from finsler.errors import InputError, short
from finsler.infra.files import read_npy
from finsler.infra.limits import check_count, check_memory, check_seed
from finsler.metrics.base import Metric

__all__ = [
    "DEFAULT_EVAL_SEED",
    "VALIDATION_SEED",
    "default_pairs",
    "load_pairs",
    "sample_pairs",
    "validation_pairs",
]

#: Seed of every environment's default evaluation set (100 uniform pairs).
DEFAULT_EVAL_SEED = 20240531
#: Seed of the validation set that training evaluates on and selects checkpoints by; it is
#: distinct from the default evaluation set, so that ``evaluate`` and ``report`` never
#: report on the pairs a checkpoint was chosen on.
VALIDATION_SEED = 20240607


def sample_pairs(metric: Metric | str, k: int, seed: int | np.random.Generator) -> np.ndarray:
    """``k`` start/goal pairs, both endpoints uniform on the domain -> ``(k, 2, dim)``
    (``metric``: a metric or a registered name).

    Deterministic for a given seed (numpy's PCG64 stream is stable across versions). A
    `numpy.random.Generator` is drawn from in place (a training run's own stream:
    fresh pairs for its trees and actor terms).

    Pair ``i`` of a seed depends on ``k`` wherever the domain draws one block of numbers
    after another (the disk: ``2 k`` radii, then ``2 k`` angles; products: factor after
    factor): for Matsumoto, Poincaré, car-like and the sphere the first 9 of
    ``sample_pairs(m, 20, s)`` are not ``sample_pairs(m, 9, s)``; on a box they are. To
    name "pair ``i`` of seed ``s``", give ``k`` too (the benchmarks' ``--only`` numbers
    pairs in the set of ``--pairs``).
    """
    if isinstance(metric, str):
        from finsler.registry import get_metric

        metric = get_metric(metric)
    # a metric, or an object with a metric's domain (the property suite's duck-typed ones)
    if not isinstance(metric, Metric) and not isinstance(getattr(metric, "domain", None),
                                                         Domain):
        raise InputError(f"metric must be a finsler.Metric (get_metric(name) for a name), got "
                         f"{describe_value(metric)}")
    k = check_count(k, "k (number of pairs)", 1)
    check_memory((2 * k, metric.dim), f"{k} pairs", hint="ask for fewer pairs", copies=4)
    rng = np.random.default_rng(check_seed(seed))
    pts = metric.domain.sample(2 * int(k), rng)
    return pts.reshape(int(k), 2, metric.dim)


def default_pairs(metric: Metric, k: int = 100) -> np.ndarray:
    """The environment's default evaluation set: ``k`` (100) uniform pairs, fixed seed."""
    return sample_pairs(metric, k, DEFAULT_EVAL_SEED)


def validation_pairs(metric: Metric, k: int = 100) -> np.ndarray:
    """The environment's validation set (checkpoint selection during training): ``k``
    uniform pairs drawn with `VALIDATION_SEED`, disjoint in seed from the default
    evaluation set."""
    return sample_pairs(metric, k, VALIDATION_SEED)


def load_pairs(path: str | os.PathLike[str], metric: Metric,
               what: str = "pairs file") -> np.ndarray:
    """Read a ``.npy`` file of start/goal pairs for ``metric`` -> float64 ``(K, 2, dim)``.

    Raises `InputError` (or `DomainError`) naming the problem if the file is
    missing or unreadable, is not a numeric array of that shape, holds NaN/inf, or holds a
    point outside the metric's domain; messages start with ``what`` (a command passes its
    option, ``--pairs``).
    """
    p = Path(path)
    name = f"{what} {short(str(p))}"
    arr = read_npy(p, what)
    if arr.ndim != 3 or arr.shape[1] != 2 or arr.shape[2] != metric.dim or arr.shape[0] < 1:
        raise InputError(
            f"{name} must hold an array of shape (K, 2, {metric.dim}) with "
            f"K >= 1 pairs for {metric.name}, got {arr.shape}"
        )
    arr = arr.astype(np.float64)
    if not np.all(np.isfinite(arr)):
        raise InputError(f"{name} contains NaN or inf")
    metric.domain.check(arr[:, 0], f"{name} starts")
    metric.domain.check(arr[:, 1], f"{name} goals")
    return arr
