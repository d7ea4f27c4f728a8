"""Batches of exact geodesics on a Ray cluster (``solve_batch(..., ray_address=...)``).

Pairs are split into chunks, one Ray task per chunk (``num_cpus=1``); each task builds the
NLP once per worker process (cached like the local pool's workers) and returns its
results, which the driver saves as the same per-pair parts as the local path, so an
interrupted cluster batch resumes without redoing finished chunks, on the cluster or
locally. What crosses the network: the metric's class and parameters, the chunk's pairs
(and initial paths, if any), the segments, seed plan and ``minmax`` / ``global_seeds``
flags; back: the :class:`GeodesicResult` objects.
Ray is imported only here, and only when a batch asks for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

from finsler.cluster import RAY_MISSING, connect_ray, require_ray
from finsler.errors import InputError

__all__ = ["RAY_MISSING", "connect_ray", "require_ray", "solve_chunks_ray"]


def _solve_chunk(worker: Callable[[tuple], tuple[int, Any]], spec: Any, ks: list[int],
                 pairs: np.ndarray, n: int, plan: Any, minmax: bool,
                 inits: np.ndarray | None = None, global_seeds: bool = True,
                 tol: float | None = None) -> list[tuple[int, Any]]:
    """Ray-task body: solve ``pairs`` ``(len(ks), 2, dim)`` (initial paths ``inits``
    ``(len(ks), n+1, dim)`` or ``None``); returns ``[(k, result)]``."""
    return [worker((spec, k, p[0], p[1], n, plan, minmax,
                    None if inits is None else inits[i], global_seeds, tol))
            for i, (k, p) in enumerate(zip(ks, pairs))]


def solve_chunks_ray(address: str, worker: Callable[[tuple], tuple[int, Any]], spec: Any,
                     pairs: np.ndarray, todo: list[int], n: int, plan: Any, minmax: bool,
                     chunk_size: int | None = None,
                     num_cpus: int | None = None,
                     initial_paths: np.ndarray | None = None,
                     global_seeds: bool = True,
                     tol: float | None = None) -> Iterator[tuple[int, Any]]:
    """Solve ``pairs[todo]`` as Ray tasks of ``chunk_size`` pairs (default: about four
    chunks per CPU of the cluster, at most 64 pairs each) with ``worker`` (the batch
    solver's per-pair function, passed in so that this module needs nothing of it);
    yields ``(k, result)`` chunk by chunk as chunks finish. ``num_cpus`` sizes a local
    instance (``address="local"``). ``initial_paths`` ``(K, n+1, dim)`` (indexed like
    ``pairs``), ``global_seeds`` and ``tol`` go to every pair's solve."""
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
            inits = None if initial_paths is None else initial_paths[ks]
            refs.append(task.remote(worker, spec, ks, pairs[ks], n, plan, minmax, inits,
                                    global_seeds, tol))
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
