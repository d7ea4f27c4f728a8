"""What every learning method shares: the loaded policy, the end of a run, the signals.

`LoadedPolicy` is the base of every method's trained policy (its config, metric,
depth, eps and source). The config every method extends, [`RunConfig`][learn.base.RunConfig], is in
`learn.run_config` (re-exported here). `finish_run` marks a run finished
(``result.json``) and builds its `TrainResult`. `StopOnSignal` lets every
training loop end cleanly on SIGINT / SIGTERM: it finishes the iteration it is in, saves a
resumable checkpoint and raises `TrainingInterrupted`.
"""

from __future__ import annotations

import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from finsler.infra.limits import check_count
from finsler.status import Result, RunStop
from learn.run_config import RunConfig, check_choice, check_hidden
from learn.storage import write_result

#: Deepest tree a depth is accepted for: ``2**40`` segments, past any memory; below it the
#: paths' memory check (`check_memory`) refuses a tree too large with its figure.
MAX_DEPTH = 40

__all__ = [
    "LoadedPolicy",
    "RunConfig",
    "StopOnSignal",
    "TrainResult",
    "TrainingInterrupted",
    "check_choice",
    "check_hidden",
    "finish_run",
]

@dataclass
class LoadedPolicy:
    """What every trained policy a method loads holds ([`learn.Policy`][learn.Policy],
    `learn.pg.PGPolicy`, `learn.seq.SeqPolicy`, a plug-in's): its run config,
    metric, evaluation depth and eps, the run it came from and the checkpoint file."""

    def __init__(self, config: Any, source: str = "", checkpoint: str = "") -> None:
        self.config = config
        self.metric = config.metric
        self.depth = config.max_depth
        self.eps = config.eval_eps
        self.source = source
        """The run folder (or package resource) the policy was loaded from."""
        self.checkpoint = checkpoint
        """File the weights came from (``checkpoint_best.pt``, ``checkpoint_latest.pt`` or
        ``policy.pt`` for shipped policies)."""

    def __repr__(self) -> str:
        return (f"{type(self).__name__}(env={self.metric.name!r}, depth={self.depth}, "
                f"source={self.source!r})")

    def check_depth(self, depth: Any) -> int:
        """``depth`` checked (a non-negative integer), or the policy's own if None."""
        d = self.depth if depth is None else depth
        return check_count(d, "depth", 0, MAX_DEPTH)


@dataclass
class TrainResult(Result):
    """Summary of a finished (or time-limited) run of any method: a
    [`finsler.status.Result`][finsler.status.Result] whose ``status`` is ``stopped_by`` (a
    `finsler.status.RunStop`: ``timesteps`` or ``minutes``, both finished runs)
    and ``wall_time`` its ``wall_seconds``."""

    run_dir: Path
    timesteps: int
    """All-inclusive evaluations of C made during training."""
    iterations: int
    wall_seconds: float
    final: dict[str, float]
    best: dict[str, float]
    history: list[dict[str, Any]] = field(repr=False, default_factory=list)
    stopped_by: RunStop = RunStop.TIMESTEPS
    """What ended the run (``result.json``'s ``stopped_by``)."""

    @property
    def status(self) -> RunStop:  # type: ignore[override]
        return self.stopped_by

    @property
    def wall_time(self) -> float:  # type: ignore[override]
        return self.wall_seconds

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the fields (``run_dir`` as text, without the metrics ``history``,
        which is ``metrics.csv``), ``status``, ``wall_time`` and ``converged``."""
        out = super().to_dict()
        out["run_dir"] = str(self.run_dir)
        out.pop("history", None)
        return out


def finish_run(run_dir: Path, history: list[dict[str, Any]], best: dict[str, Any],
               stopped_by: RunStop | str, timesteps: int, iterations: int,
               extra_final: tuple[str, ...] = (),
               extra_result: dict[str, Any] | None = None,
               signal_name: str | None = None) -> TrainResult:
    """Write ``result.json`` (the run is finished) and return its `TrainResult`
    (``final``: the last metrics row's success, lengths, throughput and ``extra_final``).
    ``stopped_by`` `RunStop.INTERRUPTED` (or a signal's name):
    the run is NOT finished; raise `TrainingInterrupted` naming ``signal_name``
    instead (the caller saved its checkpoint)."""
    if stopped_by not in (RunStop.TIMESTEPS, RunStop.MINUTES):
        name = signal_name or (stopped_by if stopped_by != RunStop.INTERRUPTED
                               else "interrupted")
        raise TrainingInterrupted(run_dir, str(name), timesteps, iterations)
    stop = RunStop(stopped_by)
    final = history[-1]
    write_result(run_dir, final, best, stop, extra_result)
    return TrainResult(
        run_dir=Path(run_dir),
        timesteps=timesteps,
        iterations=iterations,
        wall_seconds=float(final["wall_seconds"]),
        final={k: final[k] for k in ("success_rate", "mean_length",
                                     "mean_max_segment_cost", "evaluations_per_second",
                                     *extra_final)},
        best=dict(best),
        history=list(history),
        stopped_by=stop,
    )


class TrainingInterrupted(Exception):
    """Training stopped on a signal after saving a resumable checkpoint (no result.json:
    the run is unfinished and ``--resume`` continues it exactly)."""

    def __init__(self, run_dir: Path, signal_name: str, timesteps: int, iterations: int):
        self.run_dir, self.signal_name = Path(run_dir), signal_name
        self.timesteps, self.iterations = timesteps, iterations
        super().__init__(f"{signal_name}: run {self.run_dir} saved at {timesteps} evaluations "
                         f"of C (iteration {iterations}); resume it to continue")


class StopOnSignal:
    """While active (in the main thread), the first SIGINT or SIGTERM sets ``requested``
    to the signal's name, so that the training loop stops at the end of its iteration; a
    second SIGINT (Ctrl-C twice) restores the previous handlers and interrupts at once.
    A repeated SIGTERM changes nothing (a pool that is stopping may send one more)."""

    _SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        self.requested: str | None = None
        self._old: dict[int, Any] = {}

    def __enter__(self) -> StopOnSignal:
        if threading.current_thread() is threading.main_thread():
            for sig in self._SIGNALS:
                self._old[sig] = signal.getsignal(sig)
                signal.signal(sig, self._handle)
        return self

    def _handle(self, signum: int, frame: Any) -> None:
        if self.requested is not None:
            if signum == signal.SIGINT:
                self._restore()
                raise KeyboardInterrupt
            return
        self.requested = signal.Signals(signum).name

    def _restore(self) -> None:
        for sig, old in self._old.items():
            signal.signal(sig, old)
        self._old = {}

    def __exit__(self, *exc: Any) -> None:
        self._restore()
