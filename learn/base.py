"""What every learning method shares: the config mixin and the end of a run.

:class:`RunConfig` gives the config dataclasses of the midpoint learner
(:class:`learn.TrainConfig`) and of the baselines (:class:`learn.seq.SeqConfig`,
:class:`learn.pg.PGConfig`) one implementation of the type checks of their fields (configs
also come from JSON files and ``--set FIELD=VALUE``), the dict round trip of
``config.json`` and the task's depth and threshold. :func:`finish_run` marks a run finished
(``result.json``) and builds its :class:`TrainResult`. :class:`StopOnSignal` lets every
training loop end cleanly on SIGINT / SIGTERM: it finishes the iteration it is in, saves a
resumable checkpoint and raises :class:`TrainingInterrupted`.
"""

from __future__ import annotations

import dataclasses
import itertools
import signal
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import numpy as np

import finsler
from finsler.errors import InputError
from finsler.limits import check_memory
from learn.storage import write_result

__all__ = [
    "LoadedPolicy",
    "RunConfig",
    "StopOnSignal",
    "TrainResult",
    "TrainingInterrupted",
    "check_choice",
    "finish_run",
]

_C = TypeVar("_C", bound="RunConfig")
_KINDS = {"str": (str,), "int": (int,), "float": (int, float), "bool": (bool,)}


def check_choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    """Raise :class:`InputError` unless ``value`` is one of ``allowed``."""
    if value not in allowed:
        raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")


def check_hidden(hidden: tuple[int, ...], dim: int = 8, name: str = "hidden") -> None:
    """Raise :class:`InputError` unless ``hidden`` (the config field ``name``) are positive
    layer widths whose MLPs (inputs ~ ``2 * dim`` + a few) fit in memory
    (:func:`finsler.limits.check_memory`, before any network is built)."""
    if not hidden or any(h < 1 for h in hidden):
        raise InputError(f"{name} sizes must be positive, got {hidden!r}")
    widths = [2 * dim + 4, *hidden, 2 * dim]
    weights = sum((a + 1) * b for a, b in itertools.pairwise(widths))
    check_memory((weights,), f"{name} {list(hidden)} (about {weights:.3g} weights per "
                 "network)", hint="choose smaller layers", itemsize=4, copies=4)


class RunConfig:
    """Mixin for a method's config dataclass with fields ``env``, ``device``, ``depth``
    (``None`` = the task's) and ``eps`` (``None`` = the task's)."""

    env: str
    device: str
    depth: int | None
    eps: float | None

    def _check_types(self) -> None:
        """Raise :class:`InputError` naming the first field of the wrong type (fields
        annotated ``str``, ``int``, ``float``, ``bool``, ``tuple[int, ...]``, each maybe
        ``| None``, with or without ``from __future__ import annotations``; fields of other
        types are left to the config's own checks)."""
        for f in dataclasses.fields(self):  # type: ignore[arg-type]
            v = getattr(self, f.name)
            ann = f.type.__name__ if isinstance(f.type, type) else str(f.type)
            if ann.endswith(" | None"):
                if v is None:
                    continue
                ann = ann[: -len(" | None")]
            if ann == "tuple[int, ...]":
                ok = isinstance(v, (tuple, list)) and all(
                    isinstance(h, int) and not isinstance(h, bool) for h in v)
            elif ann in _KINDS:
                ok = isinstance(v, _KINDS[ann]) and (ann == "bool" or not isinstance(v, bool))
            else:
                continue
            if not ok:
                raise InputError(f"config field {f.name} must be {ann}, got {v!r}")

    def _check_env_and_device(self) -> None:
        finsler.registry.check_name(self.env, "environment")
        if self.device not in ("cpu", "cuda") and not self.device.startswith("cuda:"):
            raise InputError(f"device must be 'cpu' or 'cuda', got {self.device!r}")

    @property
    def metric(self) -> finsler.Metric:
        return finsler.get_metric(self.env)

    @property
    def max_depth(self) -> int:
        """The tree depth D of evaluation (``depth`` or the task's)."""
        return int(self.depth if self.depth is not None else self.metric.task.depth)

    @property
    def eval_eps(self) -> float:
        """The success threshold of evaluation (``eps`` or the task's)."""
        return float(self.eps if self.eps is not None else self.metric.task.eps)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)  # type: ignore[call-overload]
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        return d

    @classmethod
    def from_dict(cls: type[_C], d: dict[str, Any]) -> _C:
        """Build from a dict (unknown keys are an error naming them)."""
        if not isinstance(d, dict):
            raise InputError(f"a {cls.__name__} needs a dict, got {type(d).__name__}")
        names = {f.name for f in dataclasses.fields(cls)}  # type: ignore[arg-type]
        unknown = sorted(set(d) - names)
        if unknown:
            raise InputError(f"unknown config field(s) of {cls.__name__}: "
                             f"{', '.join(unknown)}")
        return cls(**d)

    def replace(self: _C, **changes: Any) -> _C:
        """A copy with ``changes`` (unknown fields are an error naming them)."""
        names = {f.name for f in dataclasses.fields(self)}  # type: ignore[arg-type]
        unknown = sorted(set(changes) - names)
        if unknown:
            raise InputError(f"unknown config field(s) of {type(self).__name__}: "
                             f"{', '.join(unknown)}")
        return dataclasses.replace(self, **changes)  # type: ignore[type-var]


@dataclass
class LoadedPolicy:
    """What every trained policy a method loads holds (:class:`learn.policy.Policy`,
    :class:`learn.pg.PGPolicy`, :class:`learn.seq.SeqPolicy`, a plug-in's): its run config,
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

    def _depth(self, depth: Any) -> int:
        """``depth`` checked (a non-negative integer), or the policy's own if None."""
        d = self.depth if depth is None else depth
        if not isinstance(d, (int, np.integer)) or isinstance(d, bool) or d < 0:
            raise InputError(f"depth must be a non-negative integer, got {depth!r}")
        return int(d)


@dataclass
class TrainResult:
    """Summary of a finished (or time-limited) run of any method."""

    run_dir: Path
    timesteps: int
    """All-inclusive evaluations of C made during training."""
    iterations: int
    wall_seconds: float
    final: dict[str, float]
    best: dict[str, float]
    history: list[dict[str, Any]] = field(repr=False, default_factory=list)


def finish_run(run_dir: Path, history: list[dict[str, Any]], best: dict[str, Any],
               stopped_by: str, timesteps: int, iterations: int,
               extra_final: tuple[str, ...] = (),
               extra_result: dict[str, Any] | None = None) -> TrainResult:
    """Write ``result.json`` (the run is finished) and return its :class:`TrainResult`
    (``final``: the last metrics row's success, lengths, throughput and ``extra_final``).
    ``stopped_by`` a signal name: the run is NOT finished; raise
    :class:`TrainingInterrupted` instead (the caller saved its checkpoint)."""
    if stopped_by not in ("timesteps", "minutes"):
        raise TrainingInterrupted(run_dir, stopped_by, timesteps, iterations)
    final = history[-1]
    write_result(run_dir, final, best, stopped_by, extra_result)
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
