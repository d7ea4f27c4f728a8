"""Batches of exact geodesics on a Ray cluster (``solve_batch(..., ray_address=...)``).

Pairs are split into chunks, one Ray task per chunk (``num_cpus=1``); each task builds the
NLP once per worker process (cached like the local pool's workers) and returns its
results, which the driver saves as the same per-pair parts as the local path, so an
interrupted cluster batch resumes without redoing finished chunks, on the cluster or
locally. What crosses the network: the metric's class and parameters, the chunk's pairs,
the segments, seed plan and ``minmax`` flag; back: the :class:`GeodesicResult` objects.
Ray is imported only here, and only when a batch asks for it.
"""

from __future__ import annotations

import logging
import math
import os
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from finsler.errors import InputError

__all__ = ["RAY_MISSING", "connect_ray", "require_ray", "solve_chunks_ray"]

RAY_MISSING = ("--ray needs Ray, which is not installed: pip install -e '.[distributed]' "
               "(or pip install 'ray>=2.9')")


def require_ray() -> Any:
    """The ``ray`` module, or :class:`InputError` saying how to install it."""
    try:
        import ray
    except ImportError as err:
        raise InputError(RAY_MISSING) from err
    return ray


def connect_ray(address: str, num_cpus: int | None = None) -> bool:
    """Join the Ray cluster at ``address`` (``"auto"``, ``"HOST:PORT"``, ``"ray://..."``)
    or start a local instance (``"local"``, ``num_cpus`` CPUs), quietly (no worker logs
    on the driver, no dashboard for a local instance). Returns False if Ray was already
    initialised in this process (it is then used as it is and left running), True if this
    call connected (the caller shuts it down)."""
    ray = require_ray()
    if not isinstance(address, str) or not address.strip():
        raise InputError("--ray needs an address: HOST:PORT, auto, or local")
    if ray.is_initialized():
        return False
    quiet = dict(log_to_driver=False, logging_level=logging.ERROR)
    try:
        if address == "local":
            os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
            ray.init(num_cpus=num_cpus, include_dashboard=False, **quiet)
        else:
            ray.init(address=address, **quiet)
    except (ConnectionError, RuntimeError, ValueError) as err:
        raise InputError(f"cannot connect to Ray at {address!r}: {err}") from err
    return True


def _solve_chunk(worker: Callable[[tuple], tuple[int, Any]], spec: tuple, ks: list[int],
                 pairs: np.ndarray, n: int, plan: Any, minmax: bool) -> list[tuple[int, Any]]:
    """Ray-task body: solve ``pairs`` ``(len(ks), 2, dim)``; returns ``[(k, result)]``."""
    return [worker((spec, k, p[0], p[1], n, plan, minmax)) for k, p in zip(ks, pairs)]


def solve_chunks_ray(address: str, worker: Callable[[tuple], tuple[int, Any]], spec: tuple,
                     pairs: np.ndarray, todo: list[int], n: int, plan: Any, minmax: bool,
                     chunk_size: int | None = None,
                     num_cpus: int | None = None) -> Iterator[tuple[int, Any]]:
    """Solve ``pairs[todo]`` as Ray tasks of ``chunk_size`` pairs (default: about four
    chunks per CPU of the cluster, at most 64 pairs each) with ``worker`` (the batch
    solver's per-pair function, passed in so that this module needs nothing of it);
    yields ``(k, result)`` chunk by chunk as chunks finish. ``num_cpus`` sizes a local
    instance (``address="local"``)."""
    if chunk_size is not None and (isinstance(chunk_size, bool) or chunk_size < 1):
        raise InputError(f"chunk_size must be a positive integer, got {chunk_size!r}")
    ray = require_ray()
    started = connect_ray(address, num_cpus=num_cpus)
    refs: list[Any] = []
    try:
        if chunk_size is None:
            cpus = max(1, int(ray.cluster_resources().get("CPU", 1)))
            chunk_size = min(64, max(1, math.ceil(len(todo) / (4 * cpus))))
        task = ray.remote(num_cpus=1, max_retries=1)(_solve_chunk)
        for i in range(0, len(todo), chunk_size):
            ks = todo[i:i + chunk_size]
            refs.append(task.remote(worker, spec, ks, pairs[ks], n, plan, minmax))
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield from ray.get(ready[0])
        refs = []
    finally:
        for ref in refs:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
