"""The one run loop every learning method uses, and the loading of a run's checkpoint.

A method is a subclass of [`RunLoop`][learn.loop.RunLoop] that supplies what only it knows:

* ``config_class`` (its config dataclass on `learn.run_config.RunConfig`, which
  holds every run field), ``label`` (the progress bar's), ``free_on_resume`` (the config
  fields a resume may change) and ``recorded_on_resume`` (those of them that a resume
  writes into ``config.json``), and `RunLoop.check_resume` (a method's own rule
  about what a resume may change);
* `RunLoop.setup`: networks, optimisers, generators for ``self.cfg`` (and
  `RunLoop.start`: what a NEW run does once before its first row). Before it the
  loop has set what every method needs: ``self.device`` (``cfg.device`` resolved), the
  torch threads (``cfg.threads``), ``self.metric``, ``self.dim``, ``self.depth_max`` and
  ``self.validation_pairs`` (``finsler.validation_pairs(metric, cfg.eval_pairs)``);
  `RunLoop.seeded` and `RunLoop.generators` give the seeded initialisation
  and generators;
* `RunLoop.iterate`: one iteration, adding the evaluations of C it made to
  ``timesteps`` (all-inclusive; ``timesteps_paper``, ``timesteps_derivative`` as they
  apply) and 1 to ``iteration``;
* `RunLoop.evaluation`: the method's columns of a metrics row and its candidate
  record for ``checkpoint_best.pt`` (``success_rate``, ``mean_max_segment_cost``, ...);
* `RunLoop.state_dict` / `RunLoop.load_state_dict`: everything it needs to
  resume exactly; `RunLoop.policy_state`: the weights ``checkpoint_best.pt`` keeps;
* `RunLoop.run_document`: ``config.json``'s sections about the method.

The loop does the rest, the same way for every method: the run directory (refused if not
empty, unless resumed), the resume check (only ``free_on_resume`` may differ from the saved
config), the budget (``timesteps``, or `RunLoop.has_budget`), the wall-clock limit
(``minutes``, cumulative across resumes), SIGINT / SIGTERM (finish the iteration, save,
`learn.base.TrainingInterrupted`), a metrics row and the latest checkpoint every
`RunLoop.evaluation_due` (first row at iteration 0, last row at the end), the best
checkpoint (highest validation success, ties by lower mean max segment cost) and
``result.json`` (`learn.base.finish_run`). The loop is the only place that knows
about runs. Register the method with `learn.registry.register_method`.

`load_run` opens a run directory (or a shipped policy's folder, `shipped_policies`) for a
policy loader; `resolve_device` turns a config's ``device`` into a torch device.
"""

from __future__ import annotations

import contextlib
import json
import math
import sys
import time
from abc import ABC, abstractmethod
from collections.abc import Iterator, Sequence
from importlib import resources
from pathlib import Path
from typing import Any, ClassVar

import numpy as np
import torch

import finsler
from finsler.errors import InputError
from finsler.status import RunStop
from learn.base import StopOnSignal, TrainResult, finish_run
from learn.registry import BUILTIN_MODULES
from learn.run_config import RunConfig, check_run_metric, package_versions, run_header
from learn.storage import (
    BEST_FILE,
    CONFIG_FILE,
    LATEST_FILE,
    METRICS_FILE,
    POLICY_FILE,
    RESULT_FILE,
    CorruptFileError,
    atomic_write_text,
    check_run_dir,
    load_checkpoint,
    read_json,
    restore_history,
    save_checkpoint,
    write_metrics,
)

__all__ = [
    "CHECKPOINT_FORMAT",
    "RunLoop",
    "best_record",
    "eval_columns",
    "load_run",
    "load_weights",
    "read_config_section",
    "resolve_device",
    "shipped_dir",
    "shipped_policies",
]

#: The ``format`` entry of every checkpoint (inside the sealed file of learn.storage).
CHECKPOINT_FORMAT = "learn-checkpoint-v1"
_LOAD_ERRORS = (KeyError, RuntimeError, TypeError, ValueError, IndexError)


def resolve_device(name: str) -> torch.device:
    """``cpu`` or ``cuda[:k]``; a clear `InputError` if CUDA is unavailable."""
    if name == "cpu":
        return torch.device("cpu")
    if name == "cuda" or name.startswith("cuda:"):
        if not torch.cuda.is_available():
            raise InputError(f"device {name!r} requested but CUDA is not available on this "
                             "machine (torch.cuda.is_available() is False); use --device cpu")
        return torch.device(name)
    raise InputError(f"device must be 'cpu' or 'cuda', got {name!r}")


def read_config_section(run_dir: str | Path) -> dict[str, Any]:
    """The ``config`` section of a run directory's ``config.json``
    (`CorruptFileError` if there is none)."""
    path = Path(run_dir) / CONFIG_FILE
    doc = read_json(path)
    if not isinstance(doc.get("config"), dict):
        raise CorruptFileError(f"{path} has no 'config' section")
    return doc["config"]


def eval_columns(ev: Any, suffix: str = "") -> dict[str, Any]:
    """The metrics-row columns of an evaluation (`learn.evaluation.EvalResult`):
    ``success_rate``, ``mean_length`` and ``mean_max_segment_cost`` (+ ``suffix``)."""
    return {f"success_rate{suffix}": ev.success_rate,
            f"mean_length{suffix}": round(ev.mean_length, 8),
            f"mean_max_segment_cost{suffix}": round(ev.mean_max_segment_cost, 8)}


def best_record(ev: Any, **more: Any) -> dict[str, Any]:
    """A candidate record of ``checkpoint_best.pt`` from an evaluation, then ``more``."""
    return {"success_rate": ev.success_rate,
            "mean_max_segment_cost": ev.mean_max_segment_cost,
            "mean_length": ev.mean_length, **more}


def _selection_key(record: dict[str, Any]) -> tuple[float, float, float]:
    """Best checkpoint: higher validation success (at a method's selection tolerance first,
    ``selection_success``, where it keeps one), ties by lower mean max segment cost."""
    return (record.get("selection_success", record["success_rate"]), record["success_rate"],
            -record["mean_max_segment_cost"])


class RunLoop(ABC):
    """Train one method's config into a run directory (see the module docstring).

    Counters the loop owns and every method advances in `iterate`: ``iteration``,
    ``timesteps`` (all-inclusive evaluations of C: the budget), ``timesteps_paper`` (the
    paper's count) and ``timesteps_derivative`` (evaluations whose derivative was used).
    """

    config_class: ClassVar[type[RunConfig]]
    label: ClassVar[str] = "train"
    """Progress bar label (``<label> <env>``)."""
    free_on_resume: ClassVar[tuple[str, ...]] = ("minutes", "device", "eval_pairs")
    """Config fields a resumed run may change (run control, not the run itself); the
    given values are used."""
    recorded_on_resume: ClassVar[tuple[str, ...]] = ()
    """Fields of ``free_on_resume`` that say what the run does, not only how it is run: a
    resume that changes one rewrites ``config.json`` with the new values when it starts
    (the midpoint learner's polish settings). Changes of the others (``minutes``,
    ``device``, ...) leave ``config.json`` as the run began."""
    final_columns: ClassVar[tuple[str, ...]] = ()
    """Columns of the last metrics row copied into `TrainResult.final` besides the
    success rate, lengths and throughput."""

    def __init__(self, cfg: RunConfig, run_dir: str | Path, resume: bool = False,
                 progress: bool = True) -> None:
        if not isinstance(cfg, self.config_class):
            raise InputError(f"{type(self).__name__} needs a {self.config_class.__name__}, "
                             f"got {type(cfg).__name__}")
        self.run_dir = check_run_dir(Path(run_dir), resume)
        self.progress = progress
        self._record_config = False
        if resume:
            cfg = self._resume_config(cfg)
        self.cfg: Any = cfg
        self.iteration = 0
        self.timesteps = 0
        self.timesteps_paper = 0
        self.timesteps_derivative = 0
        self.wall_before = 0.0
        self.best: dict[str, Any] = {"success_rate": -1.0, "mean_max_segment_cost": math.inf}
        self.history: list[dict[str, Any]] = []
        self._t0 = time.perf_counter()
        # what every method's setup needs, the same way for each
        self.device = resolve_device(cfg.device)
        torch.set_num_threads(cfg.threads)
        self.metric = cfg.metric
        self.dim = self.metric.dim
        self.depth_max = cfg.max_depth
        self.validation_pairs = finsler.validation_pairs(self.metric, cfg.eval_pairs)
        self.setup()
        if resume:
            latest = self.run_dir / LATEST_FILE
            if not latest.is_file():
                raise InputError(
                    f"cannot resume: {latest} is missing (the run's progress cannot be "
                    "restored; nothing was changed). Start a new run with another --out")
            self._load_state(load_checkpoint(latest))
        else:
            self.start()
            self.run_dir.mkdir(parents=True, exist_ok=True)
            atomic_write_text(self.run_dir / CONFIG_FILE, self._config_json())

    # -- what a method supplies -----------------------------------------------------------
    @abstractmethod
    def setup(self) -> None:
        """Build the networks, optimisers and generators of ``self.cfg`` (and the method's
        own counters), seeded by the config: a new run and a resumed one build the same
        before the checkpoint is loaded. ``self.device``, ``self.metric``, ``self.dim``,
        ``self.depth_max`` and ``self.validation_pairs`` are set already."""

    def check_resume(self, saved: RunConfig, resumed: RunConfig) -> None:  # noqa: B027
        """A method's own rule about resuming (called before `setup`, after the
        loop's check that only ``free_on_resume`` fields differ): ``saved`` is the run's
        ``config.json``, ``resumed`` the config the run continues with; raise
        `InputError` to refuse (default: nothing more to check)."""

    def start(self) -> None:  # noqa: B027 (optional hook)
        """What a new run does once, before its config is written (not on resume)."""

    @abstractmethod
    def iterate(self) -> None:
        """One iteration: advance ``iteration`` by 1 and the timestep counters by the
        evaluations of C made."""

    @abstractmethod
    def evaluation(self) -> tuple[dict[str, Any], dict[str, Any]]:
        """Evaluate the deterministic policy on the validation set: returns the method's
        columns of the metrics row (between the counters and the throughput) and the
        candidate best record (``success_rate``, ``mean_max_segment_cost``, then what the
        method keeps; the loop adds ``wall_seconds``)."""

    @abstractmethod
    def state_dict(self) -> dict[str, Any]:
        """Everything beyond the loop's counters that a resume needs (weights, optimiser
        and generator states); a ``counters`` entry holds the method's own counters."""

    @abstractmethod
    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore `state_dict` (a ``KeyError`` / ``RuntimeError`` / ``TypeError`` /
        ``ValueError`` / ``IndexError`` means the checkpoint does not fit the run)."""

    @abstractmethod
    def policy_state(self) -> dict[str, Any]:
        """The entries of ``checkpoint_best.pt`` a policy loader reads (the weights)."""

    @abstractmethod
    def run_document(self) -> dict[str, Any]:
        """``config.json``'s sections after ``config``, ``metric`` and ``task`` (what
        the method is, model-free or not, what its counts mean, how the best checkpoint is
        chosen; ``versions`` is added if absent)."""

    def has_budget(self) -> bool:
        """True while another iteration may start (default: ``timesteps`` not spent)."""
        return self.timesteps < self.cfg.timesteps

    def evaluation_due(self) -> bool:
        """After an iteration: write a metrics row and checkpoints now? (default: every
        ``eval_every`` iterations)."""
        return self.iteration % self.cfg.eval_every == 0

    def begin(self) -> None:  # noqa: B027 (optional hook)
        """Called when `run` starts (also on resume), before the first row."""

    def rates(self, wall: float) -> dict[str, Any]:
        """Throughput columns after ``evaluations_per_second``."""
        return {}

    def progress_fields(self, row: dict[str, Any]) -> dict[str, Any]:
        """What the progress bar shows after a metrics row."""
        return {"success": f"{row['success_rate']:.2f}"}

    def result_extra(self) -> dict[str, Any]:
        """Extra entries of ``result.json``."""
        return {}

    # -- helpers for a method's setup ------------------------------------------------------
    @contextlib.contextmanager
    def seeded(self) -> Iterator[None]:
        """A block whose torch draws (network initialisation) come from ``cfg.seed``; the
        global torch generator is as before afterwards."""
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(self.cfg.seed)
            yield

    def generators(self) -> tuple[np.random.Generator, torch.Generator]:
        """A numpy generator seeded with ``cfg.seed`` and a torch generator on the device
        seeded with ``cfg.seed + 1`` (a method saves their states in `state_dict`)."""
        gen = torch.Generator(device=self.device)
        gen.manual_seed(self.cfg.seed + 1)
        return np.random.default_rng(self.cfg.seed), gen

    # -- the loop -------------------------------------------------------------------------
    def _resume_config(self, cfg: RunConfig) -> RunConfig:
        saved = self.config_class.from_dict(read_config_section(self.run_dir))
        if cfg.env != saved.env:
            raise InputError(f"cannot resume: run {self.run_dir} trains {saved.env!r}, "
                             f"not {cfg.env!r}")
        new, old = cfg.to_dict(), saved.to_dict()
        changed = [k for k in old if k not in self.free_on_resume and new[k] != old[k]]
        if changed:
            raise InputError("cannot resume with different settings: " + ", ".join(
                f"{k} ({old[k]!r} in the run, {new[k]!r} given)" for k in changed))
        resumed = saved.replace(**{k: getattr(cfg, k) for k in self.free_on_resume})
        self.check_resume(saved, resumed)
        self._record_config = any(getattr(saved, k) != getattr(resumed, k)
                                  for k in self.recorded_on_resume)
        return resumed

    def _config_json(self) -> str:
        doc = {**run_header(self.cfg), **self.run_document()}
        doc.setdefault("versions", package_versions())
        module = type(self).__module__
        if module not in BUILTIN_MODULES:  # a method registered outside the toolkit's own
            doc["method_module"] = module
            where = getattr(sys.modules.get(module), "__file__", None)
            if where:  # to say what to import when the module is not importable
                doc["method_file"] = str(Path(where).resolve())
        return json.dumps(doc, indent=2)

    def _wall(self) -> float:
        return self.wall_before + (time.perf_counter() - self._t0)

    def _state(self) -> dict[str, Any]:
        st: dict[str, Any] = {"format": CHECKPOINT_FORMAT, "config": self.cfg.to_dict(),
                              **self.state_dict()}
        st["counters"] = {"iteration": self.iteration, "timesteps": self.timesteps,
                          "timesteps_paper": self.timesteps_paper,
                          "timesteps_derivative": self.timesteps_derivative,
                          **st.get("counters", {}), "wall_seconds": self._wall()}
        st["best"] = dict(self.best)
        st["history"] = [dict(r) for r in self.history]
        return st

    def _load_state(self, st: dict[str, Any]) -> None:
        try:
            c = st["counters"]
            self.iteration, self.timesteps = int(c["iteration"]), int(c["timesteps"])
            self.timesteps_paper = int(c.get("timesteps_paper", self.timesteps))
            self.timesteps_derivative = int(c.get("timesteps_derivative", 0))
            self.wall_before = float(c["wall_seconds"])
            self.load_state_dict(st)
            self.best = dict(st["best"])
        except _LOAD_ERRORS as err:
            raise CorruptFileError(
                f"checkpoint {self.run_dir / LATEST_FILE} does not match the run: {err}"
            ) from err
        self.history = restore_history(self.run_dir, st, self.iteration)

    def _log_and_checkpoint(self) -> dict[str, Any]:
        """A metrics row, the best checkpoint if the policy improved, the latest one."""
        columns, candidate = self.evaluation()
        wall = self._wall()
        row = {
            "iteration": self.iteration,
            "timesteps": self.timesteps,
            "timesteps_paper": self.timesteps_paper,
            "timesteps_derivative": self.timesteps_derivative,
            "wall_seconds": round(wall, 3),
            **columns,
            "evaluations_per_second": round(self.timesteps / max(wall, 1e-9), 1),
            **self.rates(wall),
        }
        self.history.append(row)
        write_metrics(self.run_dir / METRICS_FILE, self.history)
        if _selection_key(candidate) > _selection_key(self.best):
            self.best = {**candidate, "wall_seconds": wall}
            save_checkpoint(self.run_dir / BEST_FILE, {
                "format": CHECKPOINT_FORMAT, "config": self.cfg.to_dict(),
                **self.policy_state(), "eval": dict(self.best)})
        save_checkpoint(self.run_dir / LATEST_FILE, self._state())
        return row

    def run(self) -> TrainResult:
        """Train until the budget or ``minutes`` is spent; returns the summary (a signal:
        the checkpoint is saved and `learn.base.TrainingInterrupted` raised)."""
        from tqdm.auto import tqdm

        cfg = self.cfg
        total = int(cfg.timesteps)
        self._t0 = time.perf_counter()
        (self.run_dir / RESULT_FILE).unlink(missing_ok=True)  # finished again at the end
        bar = tqdm(total=total, initial=min(self.timesteps, total), unit="C",
                   unit_scale=True, disable=not self.progress,
                   desc=f"{self.label} {cfg.env}", dynamic_ncols=True)
        if self._record_config:  # a resume changed a recorded_on_resume field
            atomic_write_text(self.run_dir / CONFIG_FILE, self._config_json())
            self._record_config = False
        self.begin()
        if self.iteration == 0 and not self.history:
            self._log_and_checkpoint()
        last_logged = self.iteration
        stopped_by = RunStop.TIMESTEPS
        with StopOnSignal() as stop:
            try:
                while self.has_budget():
                    if stop.requested:
                        stopped_by = RunStop.INTERRUPTED
                        break
                    if cfg.minutes is not None and self._wall() >= 60.0 * cfg.minutes:
                        stopped_by = RunStop.MINUTES
                        break
                    before = self.timesteps
                    self.iterate()
                    bar.update(min(self.timesteps, total) - min(before, total))
                    if self.evaluation_due():
                        row = self._log_and_checkpoint()
                        last_logged = self.iteration
                        bar.set_postfix(**self.progress_fields(row))
                if self.iteration != last_logged:
                    self._log_and_checkpoint()
            finally:
                bar.close()
        return finish_run(self.run_dir, self.history, self.best, stopped_by,
                          self.timesteps, self.iteration, extra_final=self.final_columns,
                          extra_result=self.result_extra() or None,
                          signal_name=stop.requested)


def load_run(run: str | Path, checkpoint: str, config_class: type[RunConfig],
             methods: Sequence[str], env: str | None = None,
             metric_params: dict[str, Any] | None = None
             ) -> tuple[Path, Any, dict[str, Any], str]:
    """Open a run directory for a policy loader: ``(path, config, checkpoint content, file
    name loaded)``. ``checkpoint``: ``best`` (``checkpoint_best.pt``, else a shipped
    ``policy.pt``, else the latest) or ``latest``; the run's ``method`` must be one of
    ``methods``; ``env`` / ``metric_params``, if given, must be the run's
    (`learn.run_config.check_run_metric`). `InputError` / `CorruptFileError`
    name the problem."""
    path = Path(run)
    if not path.is_dir():
        raise InputError(f"run directory {str(run)!r} does not exist")
    if checkpoint not in ("best", "latest"):
        raise InputError(f"checkpoint must be 'best' or 'latest', got {checkpoint!r}")
    section = read_config_section(path)
    method = section.get("method", methods[0])
    if method not in methods:
        raise InputError(f"{path} is not a run of {' / '.join(methods)} (method {method!r})")
    cfg = config_class.from_dict(section)
    check_run_metric(cfg, f"policy {path}", env, metric_params)
    order = ((BEST_FILE, POLICY_FILE, LATEST_FILE) if checkpoint == "best"
             else (LATEST_FILE, POLICY_FILE))
    for name in order:
        if (path / name).is_file():
            return path, cfg, load_checkpoint(path / name), name
    raise InputError(f"run directory {path} holds no checkpoint ({', '.join(order)})")


def load_weights(module: Any, state: Any, path: Path) -> None:
    """``module.load_state_dict(state)``; a mismatch is a `CorruptFileError`."""
    try:
        module.load_state_dict(state)
    except _LOAD_ERRORS as err:
        raise CorruptFileError(f"checkpoint in {path} does not match its config: {err}") \
            from err


def shipped_policies() -> list[str]:
    """Environments with a policy shipped inside the package."""
    root = resources.files("learn") / "policies"
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if (p / POLICY_FILE).is_file())


def shipped_dir(name: str) -> Path:
    """The folder of the policy shipped for environment ``name`` (`shipped_policies`)."""
    return Path(str(resources.files("learn") / "policies" / name))
