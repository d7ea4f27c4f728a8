"""Batches of exact geodesics on a Ray cluster (``solve_batch(..., ray_address=...)``).

Pairs are split into chunks, one Ray task per chunk (``num_cpus=1``); each task builds the
NLP once per worker process (cached like the local pool's workers) and returns its
results, which the driver saves as the same per-pair parts as the local path, so an
interrupted cluster batch resumes without redoing finished chunks, on the cluster or
locally. What crosses the network: the metric's class and parameters, the chunk's pairs
(and initial paths, if any), the segments, seed plan, ``minmax`` / ``global_seeds`` /
``tol`` / method settings; back: the `GeodesicResult` objects. A chunk is one
batched solve (`solvers.newton.driver`) where the batched method covers the metric.
Ray is imported only here, and only when a batch asks for it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from typing import Any

from finsler.errors import InputError
from finsler.infra.cluster import RAY_MISSING, connect_ray, require_ray

__all__ = ["RAY_MISSING", "connect_ray", "require_ray", "solve_chunks_ray"]


def _solve_chunk(worker: Callable[[Any], list[tuple[int, Any]]], chunk: Any
                 ) -> list[tuple[int, Any]]:
    """Ray-task body: ``worker(chunk)`` (the batch solver's chunk function on one chunk)
    -> ``[(k, result)]``."""
    return worker(chunk)


def solve_chunks_ray(address: str, worker: Callable[[Any], list[tuple[int, Any]]],
                     job: Callable[[list[int]], Any], todo: list[int],
                     chunk_size: int | None = None,
                     num_cpus: int | None = None) -> Iterator[list[tuple[int, Any]]]:
    """Solve the pairs ``todo`` as Ray tasks of ``chunk_size`` pairs (default: about four
    chunks per CPU of the cluster, at most 64 pairs each): ``worker(job(ks))`` for each
    chunk ``ks`` (the batch solver's chunk function and job maker, passed in so that this
    module needs nothing of it); yields each chunk's ``[(k, result)]`` as chunks finish.
    ``num_cpus`` sizes a local instance (``address="local"``)."""
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
            refs.append(task.remote(worker, job(todo[i:i + chunk_size])))
        pending = list(refs)
        while pending:
            ready, pending = ray.wait(pending, num_returns=1)
            yield ray.get(ready[0])
        refs = []
    finally:
        for ref in refs:
            ray.cancel(ref, force=True)
        if started:
            ray.shutdown()
