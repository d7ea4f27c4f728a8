"""One way to run work on processes for every long command (batch solves, sweeps) that
ends cleanly on SIGINT and SIGTERM: no worker outlives the command.

``with ProcessPool(workers) as pool: for r in pool.map_unordered(func, jobs): ...`` yields
``func(job)`` as workers finish (spawned processes, so threads and CUDA are safe). Inside
the block SIGTERM in the parent is the same interruption as Ctrl-C; on either the workers
are stopped, waited for, and `PoolInterrupted` is raised. Workers ignore SIGINT, so
a Ctrl-C in a terminal reaches them only through the parent.

* Short jobs (``graceful=False``, one geodesic each): a ``multiprocessing.Pool``; on an
  interruption it is terminated at once (the caller has saved every finished job).
* Long jobs that save their own state on SIGTERM (``graceful=True``, training runs): one
  process per job, at most ``workers`` at a time. On an interruption no new job starts,
  every running job gets SIGTERM (it finishes its iteration, saves a resumable checkpoint
  and returns), and the parent waits for them (``grace`` seconds at most, then SIGKILL).
  A job whose process dies without a result (killed by the OOM killer, a segfault) stops
  the pool with ``RuntimeError``, unless ``on_death(job, exitcode)`` is given: then its
  return value stands for that job's result and the other jobs go on.

It lives in ``finsler`` because ``solvers`` and ``learn`` both use it and may not import
each other.
"""

from __future__ import annotations

import multiprocessing as mp
import queue
import signal
import threading
import time
from collections.abc import Callable, Iterable, Iterator
from typing import Any, TypeVar

__all__ = ["PoolInterrupted", "ProcessPool"]

_J = TypeVar("_J")
_R = TypeVar("_R")


class PoolInterrupted(Exception):
    """Work on processes was stopped by SIGINT / SIGTERM after its workers exited."""

    def __init__(self, signal_name: str) -> None:
        self.signal_name = signal_name
        super().__init__(f"interrupted by {signal_name}")


class _Sigterm(BaseException):
    """SIGTERM raised in the parent's main thread (like KeyboardInterrupt for SIGINT)."""


def _raise_sigterm(signum: int, frame: Any) -> None:
    raise _Sigterm


def _pool_init(initializer: Callable[[], None] | None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    if initializer is not None:
        initializer()


def _one_job(func: Callable[[Any], Any], k: int, job: Any, results: Any,
             initializer: Callable[[], None] | None) -> None:
    """Body of a graceful worker: one job, its result (or error text) on the queue."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if initializer is not None:
        initializer()
    try:
        results.put((k, True, func(job)))
    except BaseException as err:  # reported to the parent, which raises it
        results.put((k, False, f"{type(err).__name__}: {err}"))


class ProcessPool:
    """See the module docstring."""

    def __init__(self, workers: int, initializer: Callable[[], None] | None = None,
                 graceful: bool = False, grace: float = 300.0,
                 on_death: Callable[[Any, int], Any] | None = None) -> None:
        if on_death is not None and not graceful:
            raise ValueError("on_death needs graceful=True (one process per job)")
        self.workers, self.initializer = max(1, int(workers)), initializer
        self.graceful, self.grace = graceful, float(grace)
        self.on_death = on_death
        self._ctx = mp.get_context("spawn")
        self._pool: Any = None
        self._running: dict[int, Any] = {}
        self._results: Any = None
        self._old: Any = None

    def __enter__(self) -> ProcessPool:
        self._main = threading.current_thread() is threading.main_thread()
        if not self.graceful:
            self._pool = self._ctx.Pool(processes=self.workers, initializer=_pool_init,
                                        initargs=(self.initializer,))
        if self._main:
            self._old = signal.getsignal(signal.SIGTERM)
            signal.signal(signal.SIGTERM, _raise_sigterm)
        return self

    def map_unordered(self, func: Callable[[_J], _R], jobs: Iterable[_J]) -> Iterator[_R]:
        """``func(job)`` for every job, results in the order they finish."""
        jobs = list(jobs)
        if not self.graceful:
            return self._pool.imap_unordered(func, jobs)
        return self._each_in_process(func, jobs)

    def _each_in_process(self, func: Callable[[_J], _R], jobs: list[_J]) -> Iterator[_R]:
        results = self._ctx.Queue()
        self._results = results
        todo = list(enumerate(jobs))
        done = 0
        while done < len(jobs):
            while todo and len(self._running) < self.workers:
                k, job = todo.pop(0)
                p = self._ctx.Process(target=_one_job,
                                      args=(func, k, job, results, self.initializer))
                p.start()
                self._running[k] = p
            try:
                k, ok, value = results.get(timeout=1.0)
            except queue.Empty:
                for k2, p in list(self._running.items()):
                    if not p.is_alive() and p.exitcode not in (0, None):
                        if self.on_death is None:
                            raise RuntimeError(f"worker of job {k2} died (exit code "
                                               f"{p.exitcode})") from None
                        self._running.pop(k2).join()
                        done += 1
                        yield self.on_death(jobs[k2], p.exitcode)
                continue
            if k not in self._running:  # a late word from a job already counted as dead
                continue
            self._running.pop(k).join()
            done += 1
            if not ok:
                raise RuntimeError(value)
            yield value

    def _stop_running(self) -> None:
        """SIGTERM every running job, wait for each to save and exit; SIGKILL laggards."""
        for p in self._running.values():
            if p.is_alive():
                p.terminate()  # SIGTERM: the job saves and returns
        deadline = time.monotonic() + self.grace
        while any(p.is_alive() for p in self._running.values()) and \
                time.monotonic() < deadline:
            try:  # keep the queue flowing so that no worker blocks on its last put
                self._results.get(timeout=0.2)
            except queue.Empty:
                pass
        for p in self._running.values():
            if p.is_alive():
                p.kill()
            p.join()
        self._running.clear()

    def __exit__(self, exc_type: Any, exc: Any, tb: Any) -> None:
        interrupted = exc_type is not None and issubclass(exc_type,
                                                          (KeyboardInterrupt, _Sigterm))
        old_int = None
        try:
            if self._main:  # a second signal while stopping must not cut the clean-up
                signal.signal(signal.SIGTERM, signal.SIG_IGN)
                old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
            if self._pool is not None:
                if exc_type is None:
                    self._pool.close()
                else:
                    self._pool.terminate()  # SIGTERM to every worker
                self._pool.join()
            else:
                self._stop_running()
        finally:
            if self._main:
                signal.signal(signal.SIGTERM, self._old)
                signal.signal(signal.SIGINT, old_int)
        if interrupted:
            name = "SIGINT" if issubclass(exc_type, KeyboardInterrupt) else "SIGTERM"
            raise PoolInterrupted(name) from None
