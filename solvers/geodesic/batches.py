"""Many pairs in one call (`solve_batch`): the pairs cut into chunks, the chunks solved
in this process, in worker processes or as Ray tasks, every finished pair saved at once
so an interrupted batch resumes.

A chunk is one batched solve of its pairs (`solvers.geodesic.pair_solver.solve_pairs`; with
``tol`` each pair refined on its own, `solvers.geodesic.tolerance.solve_to_tol`); a worker
process rebuilds the metric from its [`MetricSpec`][finsler.spec.MetricSpec] once
(``spec.build()`` returns the registry's shared instance, with what it derived). The
one vectorised Newton solve of many (pair, seed) problems is `solvers.newton.driver`; this
module only schedules and stores.
"""

from __future__ import annotations

import dataclasses
import os
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from finsler.errors import InputError, short
from finsler.infra.files import OutputError, atomic_write_bytes
from finsler.infra.limits import check_count
from finsler.infra.pool import ProcessPool
from finsler.metrics.base import Metric
from solvers.geodesic.pair_solver import check_initial_paths, resolve_method, solve_pairs
from solvers.geodesic.request import SolveRequest, seed_plan
from solvers.geodesic.tolerance import TOL_MAX_SEGMENTS, check_tol, solve_to_tol
from solvers.inputs import as_metric, check_pairs, check_segments
from solvers.newton.backends import backend_for
from solvers.result import GeodesicResult, SolverError
from solvers.seeding.plans import SeedPlan

__all__ = ["NEWTON_POOL_MIN", "NEWTON_ROWS", "BatchJob", "Chunk", "check_batch", "run_batch",
           "solve_batch"]


@dataclass(frozen=True)
class Chunk:
    """The pairs of a batch that one batched solve takes (in this process, a worker
    process or a Ray task): the request, the pairs' indices in the batch, the pairs
    ``(k, 2, dim)`` and their initial paths or None. Pickles by the metric's spec
    (`SolveRequest`)."""

    request: SolveRequest
    ks: list[int]
    pairs: np.ndarray
    inits: np.ndarray | None = None


def _solve_chunk(chunk: Chunk) -> list[tuple[int, GeodesicResult]]:
    """The pairs of a chunk (checked by `check_batch`): one batched solve (each pair
    refined on its own with ``tol``) -> ``[(index, result)]``."""
    req, ks, pairs, inits = chunk.request, chunk.ks, chunk.pairs, chunk.inits
    if req.tol is not None:
        return [(k, solve_to_tol(req, p[0], p[1], time.perf_counter(),
                                 initial=() if inits is None else (inits[i],)))
                for i, (k, p) in enumerate(zip(ks, pairs, strict=True))]
    given = [[] if inits is None else [("initial0", inits[i])] for i in range(len(ks))]
    res = solve_pairs(req, np.asarray(pairs), given)
    return list(zip(ks, res, strict=True))


#: Rows (pair x seed problems) per batched Newton solve of `solve_batch`: enough
#: that array operations dominate Python overhead (measured with ``benchmarks/peers.py
#: --throughput``: Randers, 3 seeds per pair, 0.53 / 0.35 / 0.27 ms per pair with 192 /
#: 384 / 1536 rows); the pairs of a chunk are saved together.
NEWTON_ROWS = 16384


def _chunk_pairs(plan: SeedPlan, global_seeds: bool) -> int:
    """Pairs per batched chunk: `NEWTON_ROWS` over the plan's seeds per pair."""
    seeds = (1 + 2 * len(plan.bulges) + plan.random + int(plan.graph) + plan.restarts
             if global_seeds else 1)
    return int(np.clip(NEWTON_ROWS // max(seeds, 1), 16, 4096))


#: ``solve_batch`` with the Newton method uses worker processes by default only from this
#: many pairs on (starting a process costs seconds of imports).
NEWTON_POOL_MIN = 1024


class _BatchStore:
    """Per-pair result files of a resumable `solve_batch` (pickle, atomic rename)."""

    def __init__(self, folder: Any, metric: Metric, n: int, plan: SeedPlan, minmax: bool,
                 global_seeds: bool = True, tol: float | None = None):
        import pathlib

        self.folder = pathlib.Path(folder)
        try:
            self.folder.mkdir(parents=True, exist_ok=True)
        except OSError as err:
            raise OutputError(f"cannot create the folder of resumable parts {self.folder}: "
                              f"{err.strerror}") from err
        self.key = (repr(metric), int(n), repr(plan), bool(minmax), bool(global_seeds),
                    None if tol is None else float(tol))

    def _path(self, k: int) -> Any:
        return self.folder / f"pair_{k:07d}.pkl"

    def load(self, k: int, pair: np.ndarray, init: np.ndarray | None = None
             ) -> GeodesicResult | None:
        """The saved result of pair ``k`` if it was solved from the same pair ``(2, dim)``
        and initial path (``None``: none), else ``None``."""
        import pickle

        path = self._path(k)
        if not path.is_file():
            return None
        try:
            with path.open("rb") as fh:
                key, saved_pair, saved_init, result = pickle.load(fh)
        except Exception:  # a corrupt or foreign file is recomputed, never trusted
            return None
        if key != self.key or not np.array_equal(saved_pair, pair):
            return None
        if (saved_init is None) != (init is None) or (
                init is not None and not np.array_equal(saved_init, init)):
            return None
        return result

    def save(self, k: int, pair: np.ndarray, result: GeodesicResult,
             init: np.ndarray | None = None) -> None:
        import pickle

        saved_init = None if init is None else np.array(init)
        atomic_write_bytes(self._path(k), pickle.dumps((self.key, np.array(pair), saved_init,
                                                        result)), "resumable part")


def solve_batch(
    metric: Metric | str,
    pairs: Any,
    segments: int | None = None,
    *,
    seeds: SeedPlan | None = None,
    minmax: bool = False,
    workers: int | None = None,
    progress: bool = True,
    checkpoint_dir: str | os.PathLike[str] | None = None,
    ray_address: str | None = None,
    chunk_size: int | None = None,
    initial_paths: Any = None,
    global_seeds: bool = True,
    tol: float | None = None,
    method: str = "auto",
    device: Any = None,
    strict: bool = False,
    names: tuple[str, str] = ("pairs[:, 0] (starts)", "pairs[:, 1] (goals)"),
) -> list[GeodesicResult]:
    """Solve every pair of ``pairs`` ``(K, 2, dim)``; results in the order of the pairs.

    ``workers`` processes (default: the CPU count, at most ``K``; ``1`` runs in this
    process); each worker builds the NLP once and reuses it for all its pairs. A tqdm bar
    shows progress unless ``progress=False``. Same inputs give the same results.

    With ``checkpoint_dir``, every finished pair is saved there at once (written, then
    renamed), and a rerun with the same pairs, segments, seeds and ``minmax`` reuses
    them: an interrupted batch resumes without losing finished work. Files saved for
    other inputs are ignored and recomputed.

    With ``ray_address`` (``"local"`` starts a local Ray instance of ``workers`` CPUs;
    ``"auto"`` or ``"HOST:6379"`` joins a running cluster) the pairs are solved as Ray
    tasks of ``chunk_size`` pairs (default: about four chunks per CPU of the cluster, at
    most 64 pairs) by `solvers.geodesic.distributed`; every finished chunk's pairs are saved
    as the same parts as above, and the results equal the local ones.

    ``initial_paths`` ``(K, m+1, dim)``: one caller-given initial path per pair (e.g. a
    learned policy's paths, or exact paths of another size ``m``: resampled to ``n + 1``
    points), solved as ``solve_geodesic(initial=[path])``. With ``global_seeds=True`` (what
    ``geodesics solve --warm-start`` does) the path is one more start of the pair's batched
    solve, beside the global seeds, and restarts refine the best of the plan's own starts:
    never a worse optimum than without it. With ``False`` only that path is solved (a local
    polish of a path already near its optimum; from a learned path it is no faster than the
    global seeds and can end worse: ``docs/guides/warm-starts.md``).
    ``tol``: every pair solved to that relative accuracy of its length
    ([`solve_geodesic`][solvers.geodesic.solve.solve_geodesic]).

    ``method`` / ``device``: as in [`solve_geodesic`][solvers.geodesic.solve.solve_geodesic]. With
    the batched Newton method (the default where it covers the metric) the pairs are solved in
    chunks of about `NEWTON_ROWS` (pair, seed) problems, every problem of a chunk in
    one batch; the default ``workers`` is then 1 below `NEWTON_POOL_MIN` pairs (the
    batch is vectorised; processes pay off only for many chunks), else the CPU count.

    ``strict=True`` raises `SolverError` (the list of results attached) if a pair
    did not converge (min-max included), after every pair was solved and saved; the default
    (``False``) returns every result with its status. ``names``: how error
    messages name the starts and goals (the command line names ``--start`` / ``--goal``).

    The input is checked here, once (`_check_batch`); the chunks trust it.
    """
    job = check_batch(metric, pairs, segments, seeds=seeds, minmax=minmax, workers=workers,
                      ray_address=ray_address, chunk_size=chunk_size,
                      initial_paths=initial_paths, global_seeds=global_seeds, tol=tol,
                      method=method, device=device, names=names)
    return run_batch(job, progress=progress, checkpoint_dir=checkpoint_dir, strict=strict)


def run_batch(job: BatchJob, *, progress: bool = True,
              checkpoint_dir: str | os.PathLike[str] | None = None,
              strict: bool = False) -> list[GeodesicResult]:
    """`solve_batch` of a checked `BatchJob` (`check_batch`): nothing
    is checked again. A caller that must do something between the checks and the first
    solve (the command line checks its ``--out`` path there) calls the two steps."""
    if not isinstance(job, BatchJob):
        raise InputError(f"run_batch needs a BatchJob (check_batch), got {type(job).__name__}")
    req = job.request
    store = (_BatchStore(checkpoint_dir, req.metric, req.segments, req.plan, req.minmax,
                         req.global_seeds, req.tol) if checkpoint_dir else None)
    results = _solve_checked(job, store, progress)
    if strict:
        bad = [k for k, r in enumerate(results)
               if not (r.converged and (r.minmax is None or r.minmax.converged))]
        if bad:
            raise SolverError(f"{req.metric.name}: {len(bad)} of {len(results)} pairs did not "
                              f"converge (first: pair {bad[0]}, status "
                              f"{results[bad[0]].status.label})", results)
    return results


@dataclass(frozen=True)
class BatchJob:
    """A batch's checked input (`check_batch`): what `run_batch` and the chunks take
    without checking again: the solve request, the pairs ``(K, 2, dim)`` (read-only),
    the initial paths ``(K, n+1, dim)`` or None, and how the chunks are run."""

    request: SolveRequest
    pairs: np.ndarray
    inits: np.ndarray | None = None
    workers: int = 1
    ray_address: str | None = None
    chunk_size: int | None = None

    @property
    def metric(self) -> Metric:
        """The request's metric."""
        return self.request.metric

    @property
    def segments(self) -> int:
        """The request's size ``n``."""
        return self.request.segments

    def with_initial_paths(self, paths: Any) -> BatchJob:
        """This job with one initial path per pair ``(K, m+1, dim)`` (checked: finite,
        in the domain, ending at the pair's start and goal; resampled to ``n + 1``
        points), e.g. a learned policy's paths computed once the pairs were checked."""
        inits = check_initial_paths(self.metric, self.pairs, self.segments, paths)
        return dataclasses.replace(self, inits=inits)

    def inits_of(self, ks: Sequence[int] | int) -> np.ndarray | None:
        return None if self.inits is None else self.inits[ks]

    def chunk(self, ks: list[int]) -> Chunk:
        """The chunk of the pairs ``ks``."""
        return Chunk(self.request, ks, self.pairs[ks], self.inits_of(ks))


#: Most worker processes of one `solve_batch` (each holds a copy of the metric's NLPs).
MAX_WORKERS = 256


def _positive_int(value: Any, name: str, high: int | None = None) -> None:
    check_count(value, name, 1, high)


def check_batch(metric: Metric | str, pairs: Any, segments: int | None = None, *,
                seeds: SeedPlan | None = None, minmax: bool = False,
                workers: int | None = None, ray_address: str | None = None,
                chunk_size: int | None = None, initial_paths: Any = None,
                global_seeds: Any = True, tol: float | None = None, method: str = "auto",
                device: Any = None,
                names: tuple[str, str] = ("pairs[:, 0] (starts)", "pairs[:, 1] (goals)")
                ) -> BatchJob:
    """Step 1 of `solve_batch` (same arguments): every input checked once, before any
    work (and, with Ray, before any file is made); `run_batch` solves the job."""
    m = as_metric(metric)
    arr = check_pairs(m, pairs, names)
    n = check_segments(m, segments)
    how = resolve_method(m, method)
    if device is not None:
        backend_for(device)  # a bad device fails here, before any work
    plan = seed_plan(m, seeds, how)
    if workers is None:
        workers = os.cpu_count() or 1
        if how == "newton" and arr.shape[0] < NEWTON_POOL_MIN:
            workers = 1
    _positive_int(workers, "workers", MAX_WORKERS)
    if chunk_size is not None:
        _positive_int(chunk_size, "chunk_size")
    if ray_address is not None and not isinstance(ray_address, str):
        raise InputError(f"ray_address must be a str ('auto', 'local' or host:port), got "
                         f"{type(ray_address).__name__} {short(repr(ray_address), 80)}")
    if ray_address is not None:
        from finsler.infra.cluster import probe_address, require_ray

        require_ray()  # before any file is made
        probe_address(ray_address)  # a wrong address fails in seconds
    if not isinstance(global_seeds, (bool, np.bool_)):
        raise InputError(f"global_seeds must be True or False, got {global_seeds!r}")
    inits = check_initial_paths(m, arr, n, initial_paths)
    if not global_seeds and inits is None:
        raise InputError("global_seeds=False needs initial_paths (one path per pair)")
    tol_ = None if tol is None else check_tol(m, n, tol, TOL_MAX_SEGMENTS)[0]
    arr = arr.copy()  # the caller's array stays the caller's
    arr.flags.writeable = False  # checked: nobody changes it before the solve
    req = SolveRequest(m, n, plan, how, bool(global_seeds), bool(minmax), tol_,
                       TOL_MAX_SEGMENTS, device)
    return BatchJob(req, arr, inits, int(workers), ray_address,
                    None if chunk_size is None else int(chunk_size))


def _chunks(job: BatchJob, todo: list[int]) -> list[list[int]]:
    """Step 2: the pairs still to solve cut into chunks (one batched Newton solve each, of
    about `NEWTON_ROWS` problems; by IPOPT one pair each; several per worker so finished
    work is kept)."""
    size = 1
    if job.request.method == "newton":
        size = _chunk_pairs(job.request.plan, job.request.global_seeds)
    if job.workers > 1:
        size = max(1, min(size, -(-len(todo) // (4 * job.workers))))
    return [todo[i:i + size] for i in range(0, len(todo), size)]


def _solve_checked(job: BatchJob, store: _BatchStore | None, progress: bool
                   ) -> list[GeodesicResult]:
    """Step 3: the pairs saved by an earlier run loaded, the others solved in this process,
    in worker processes or as Ray tasks, every finished chunk saved at once."""
    from tqdm.auto import tqdm

    m, arr = job.metric, job.pairs
    K = arr.shape[0]
    results: list[GeodesicResult | None] = [None] * K
    if store is not None:
        for k in range(K):
            results[k] = store.load(k, arr[k], job.inits_of(k))
    todo = [k for k in range(K) if results[k] is None]
    chunks = _chunks(job, todo)
    workers = int(min(job.workers, max(len(chunks), 1)))
    bar = tqdm(total=K, desc=f"solve {m.name}", disable=not progress, unit="pair",
               initial=K - len(todo))

    def take(done: list[tuple[int, GeodesicResult]]) -> None:
        for k, res in done:
            results[k] = res
            if store is not None:
                store.save(k, arr[k], res, job.inits_of(k))
        bar.update(len(done))

    try:
        if job.ray_address is not None and todo:
            from solvers.geodesic.distributed import solve_chunks_ray

            local_cpus = int(min(workers, len(todo)))
            for done in solve_chunks_ray(job.ray_address, _solve_chunk, job.chunk, todo,
                                         job.chunk_size, num_cpus=local_cpus):
                take(done)
        elif workers == 1 or len(chunks) <= 1:
            for ks in chunks:
                take(_solve_chunk(job.chunk(ks)))
        else:
            with ProcessPool(workers) as pool:
                for done in pool.map_unordered(_solve_chunk,
                                               [job.chunk(ks) for ks in chunks]):
                    take(done)
    finally:
        bar.close()
    return [r for r in results if r is not None]
