"""Sweeps: many runs ``(env, variant, seed)`` on a local process pool or on a Ray cluster.

Every run is its own run directory ``OUT/<env>/<variant>/seed-<s>/`` (the layout that the
learning-curve plots read) and is made by `learn.runs.run_one`: a finished run is
skipped, an unfinished one resumed, an absent one started. So a sweep that was killed is
finished by running the same sweep again, and only the unfinished runs do any work.

``OUT/sweep.json`` (rewritten atomically after every run) holds the plan (environments,
variants, seeds, budgets, overrides) and, per run, its status.

Backends:

* local (default): a pool of ``workers`` processes (spawn context, one torch thread per
  run) training straight into ``OUT``;
* Ray (``ray_address="local"`` starts a local Ray instance, ``"auto"`` or
  ``"HOST:6379"`` joins a running cluster): one Ray task per run (``num_cpus=1``). A
  cluster's workers do not share ``OUT``'s filesystem, so each task is sent the files its
  run directory already has (to resume), trains in a temporary directory on the worker
  and returns the run directory's files, which the driver writes into ``OUT`` (each file
  atomically, ``result.json`` last). Ray is imported only for this backend.

Python API::

    plan = plan_sweep(["matsumoto"], ["midpoint", "paper"], seeds=3, timesteps=10**6)
    result = run_sweep(plan, "runs/sweep", workers=2)        # or ray_address="auto"
    result.failed, result.rows()
"""

from __future__ import annotations

import dataclasses
import importlib
import json
import os
import tempfile
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from finsler.errors import InputError
from finsler.infra.cluster import connect_ray
from finsler.status import Result, RunAction, RunStatus, SweepStatus, json_ready
from learn.registry import find_variant, get_method
from learn.runs import VARIANTS, load_run_config, make_config, run_one, run_status
from learn.storage import (
    CONFIG_FILE,
    LATEST_FILE,
    METRICS_FILE,
    RESULT_FILE,
    atomic_write_bytes,
    atomic_write_text,
)

__all__ = [
    "SWEEP_FILE",
    "RunOutcome",
    "RunSpec",
    "SweepPlan",
    "SweepResult",
    "connect_ray",
    "plan_sweep",
    "read_run_files",
    "run_sweep",
    "write_run_files",
]

SWEEP_FILE = "sweep.json"

#: Fields a sweep sets itself (``--seeds``, ``--timesteps``, ``--minutes``, the variant).
_SWEEP_FIELDS = frozenset({"env", "method", "seed", "timesteps", "minutes", "device"})



# ----------------------------------------------------------------------------------------
# the plan
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep."""

    env: str
    variant: str
    seed: int

    @property
    def rel_dir(self) -> str:
        """``<env>/<variant>/seed-<s>`` (relative to the sweep's folder)."""
        return f"{self.env}/{self.variant}/seed-{self.seed}"

    def path(self, out: str | os.PathLike[str]) -> Path:
        return Path(out) / self.env / self.variant / f"seed-{self.seed}"


@dataclass(frozen=True)
class SweepPlan:
    """Environments x variants x seeds ``0..seeds-1``, with budgets and config overrides
    (``overrides[variant]``: the fields given to that variant's config) and the modules of
    methods registered outside the toolkit, which every worker imports first."""

    envs: tuple[str, ...]
    variants: tuple[str, ...]
    seeds: int
    timesteps: int | None = None
    minutes: float | None = None
    overrides: Mapping[str, Mapping[str, Any]] = field(default_factory=dict)
    modules: tuple[str, ...] = ()

    def runs(self) -> list[RunSpec]:
        """Every run, env-major then variant then seed."""
        return [RunSpec(e, v, s) for e in self.envs for v in self.variants
                for s in range(self.seeds)]

    def config(self, spec: RunSpec) -> Any:
        """The config of one run (the method's config dataclass)."""
        return make_config(spec.env, spec.variant, seed=spec.seed, timesteps=self.timesteps,
                           minutes=self.minutes, **dict(self.overrides.get(spec.variant, {})))

    def to_dict(self) -> dict[str, Any]:
        return {
            "envs": list(self.envs),
            "variants": list(self.variants),
            "seeds": self.seeds,
            "timesteps": self.timesteps,
            "minutes": self.minutes,
            "overrides": {v: _jsonable(dict(o)) for v, o in self.overrides.items()},
            "modules": list(self.modules),
        }


def _jsonable(obj: Any) -> Any:
    return json.loads(json.dumps(obj, default=list))


def _names(what: str, items: Iterable[str], known: Sequence[str],
           hint: str = "") -> tuple[str, ...]:
    out: list[str] = []
    for item in items:
        name = str(item).strip()
        if name not in known:
            raise InputError(f"unknown {what} {name!r}; known: {', '.join(known)}{hint}")
        if name in out:
            raise InputError(f"{what} {name!r} is listed twice")
        out.append(name)
    if not out:
        raise InputError(f"give at least one {what}")
    return tuple(out)


def _config_dict(cfg: Any) -> dict[str, Any]:
    return cfg.to_dict() if hasattr(cfg, "to_dict") else dataclasses.asdict(cfg)


def plan_sweep(envs: Iterable[str], variants: Iterable[str], seeds: int,
               timesteps: int | None = None, minutes: float | None = None,
               overrides: Mapping[str, Any] | None = None) -> SweepPlan:
    """Check and build a sweep's plan; raises `InputError` naming the first problem.

    ``overrides`` (field -> value) go to every variant whose config class has the field
    (the midpoint family's `learn.TrainConfig`, or the seq / pg configs); a field
    that no selected variant has is an error. Every run's config is built once here, so
    impossible values fail before any work.
    """
    import finsler

    env_t = _names("environment", envs, finsler.list_metrics())
    var_t = _names("variant", variants, list(VARIANTS),
                   " (a method of your own: --method-module FILE.py)")
    if isinstance(seeds, bool) or not isinstance(seeds, int) or seeds < 1:
        raise InputError(f"seeds must be a positive integer (runs use seeds 0..N-1), "
                         f"got {seeds!r}")
    if timesteps is not None and (isinstance(timesteps, bool) or not isinstance(timesteps, int)
                                  or timesteps < 1):
        raise InputError(f"timesteps must be a positive integer, got {timesteps!r}")
    if minutes is not None and not (isinstance(minutes, (int, float)) and 0 < minutes < 1e9):
        raise InputError(f"minutes must be positive and finite, got {minutes!r}")
    over = dict(overrides or {})
    for key in over:
        if key in _SWEEP_FIELDS:
            raise InputError(f"the sweep sets {key!r} itself (use --seeds, --timesteps, "
                             f"--minutes, --envs, --methods); it cannot be overridden")
    fields_of: dict[str, set[str]] = {}
    for v in var_t:
        try:
            cls = type(make_config(env_t[0], v))
        except ImportError as err:
            raise InputError(f"variant {v!r} is not available: {err}") from err
        fields_of[v] = {f.name for f in dataclasses.fields(cls)}
    unused = [k for k in over if not any(k in f for f in fields_of.values())]
    if unused:
        raise InputError(f"unknown config field(s) {', '.join(map(repr, unused))} for "
                         f"variants {', '.join(var_t)}")
    per_variant = {v: {k: val for k, val in over.items() if k in fields_of[v]} for v in var_t}
    methods = [find_variant(v)[0] for v in var_t]
    modules = tuple(sorted({m.module for m in methods if not m.builtin}))
    plan = SweepPlan(env_t, var_t, int(seeds), timesteps,
                     None if minutes is None else float(minutes), per_variant, modules)
    for e in env_t:
        for v in var_t:
            plan.config(RunSpec(e, v, 0))  # validates every (env, variant) config
    return plan


def check_existing(plan: SweepPlan, out: str | os.PathLike[str]) -> None:
    """Raise `InputError` if a run directory in ``out`` was made with settings other
    than the plan's (only the fields its method lets a resume change may differ, e.g.
    ``minutes``, ``device``, ``eval_pairs``)."""
    for spec in plan.runs():
        path = spec.path(out)
        if run_status(path) is RunStatus.ABSENT:
            continue
        cfg = load_run_config(path)
        free = get_method(cfg.method).trainer.free_on_resume
        saved = _config_dict(cfg)
        want = _config_dict(plan.config(spec))
        diff = [k for k in sorted(set(saved) | set(want)) if k not in free
                and saved.get(k) != want.get(k)]
        if diff:
            raise InputError(
                f"run {path} was made with other settings than this sweep's: "
                + ", ".join(f"{k} ({saved.get(k)!r} there, {want.get(k)!r} now)"
                            for k in diff[:4])
                + "; choose another --out or the run's settings")


# ----------------------------------------------------------------------------------------
# outcomes
# ----------------------------------------------------------------------------------------
@dataclass
class RunOutcome:
    """What happened to one run: ``action`` is a `finsler.status.RunAction`,
    ``skipped``, ``resumed``, ``started``, ``failed`` or ``pending`` (not reached, e.g.
    interrupted); ``result`` is the run's ``result.json`` (None unless finished)."""

    spec: RunSpec
    action: RunAction = RunAction.PENDING
    result: dict[str, Any] | None = None
    error: str | None = None
    seconds: float = 0.0
    """Wall seconds of this sweep's work on the run (0 for skipped runs)."""

    def row(self) -> dict[str, Any]:
        """A flat summary: env, variant, seed, action, stopped_by, timesteps, wall seconds
        of training (cumulative), final validation success rate, error."""
        r = self.result or {}
        final = r.get("final") or {}
        return {
            "env": self.spec.env,
            "variant": self.spec.variant,
            "seed": self.spec.seed,
            "action": self.action,
            "stopped_by": r.get("stopped_by"),
            "timesteps": r.get("timesteps"),
            "wall_seconds": r.get("wall_seconds"),
            "success_rate": final.get("success_rate"),
            "error": self.error,
        }


@dataclass
class SweepResult(Result):
    """All outcomes of `run_sweep`, in the plan's order (a
    [`finsler.status.Result`][finsler.status.Result]: ``status`` is a `finsler.status.SweepStatus`
    from the runs' actions, ``wall_time`` is ``seconds``)."""

    plan: SweepPlan
    out: Path
    backend: str
    outcomes: list[RunOutcome]
    seconds: float

    @property
    def failed(self) -> list[RunOutcome]:
        return [o for o in self.outcomes if o.action is RunAction.FAILED]

    @property
    def status(self) -> SweepStatus:  # type: ignore[override]
        """``failed`` if a run failed, else ``interrupted`` if a run was not reached, else
        ``completed``."""
        if self.failed:
            return SweepStatus.FAILED
        if any(o.action is RunAction.PENDING for o in self.outcomes):
            return SweepStatus.INTERRUPTED
        return SweepStatus.COMPLETED

    @property
    def wall_time(self) -> float:
        """Seconds of the whole sweep (``seconds``)."""
        return float(self.seconds)

    def rows(self) -> list[dict[str, Any]]:
        return [o.row() for o in self.outcomes]

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dict: out, backend, status, converged, wall_time and one row per run
        (`RunOutcome.row`)."""
        return json_ready({"out": str(self.out), "backend": self.backend,
                           "status": self.status.label, "converged": self.converged,
                           "wall_time": self.wall_time, "runs": self.rows()})


def _write_sweep_json(out: Path, plan: SweepPlan, backend: dict[str, Any],
                      outcomes: list[RunOutcome]) -> None:
    runs = []
    for o in outcomes:
        row = o.row()
        runs.append({"dir": o.spec.rel_dir, "status": run_status(o.spec.path(out)),
                     **{k: v for k, v in row.items() if v is not None or k == "action"}})
    doc = {**plan.to_dict(), **backend, "runs": runs}
    atomic_write_text(out / SWEEP_FILE, json.dumps(doc, indent=2))


# ----------------------------------------------------------------------------------------
# running one run (in a worker process or a Ray task)
# ----------------------------------------------------------------------------------------
def _set_threads() -> None:
    import torch

    torch.set_num_threads(1)


def _run_local(spec: RunSpec, out: str, timesteps: int | None, minutes: float | None,
               overrides: dict[str, Any], modules: tuple[str, ...] = ()) -> dict[str, Any]:
    """Worker-process body: import the plan's method ``modules``, then ``run_one`` into
    ``out``; exceptions come back as text."""
    t0 = time.perf_counter()
    _set_threads()
    try:
        for module in modules:
            importlib.import_module(module)
        res = run_one(spec.env, spec.variant, spec.seed, out, timesteps=timesteps,
                      minutes=minutes, progress=False, **overrides)
        return {"action": res.pop("action"), "result": res,
                "seconds": time.perf_counter() - t0}
    except Exception as err:  # reported per run; the other runs go on
        return {"action": RunAction.FAILED, "error": _describe(err),
                "traceback": traceback.format_exc(), "seconds": time.perf_counter() - t0}


def _died(job: tuple, exitcode: int) -> tuple[int, dict[str, Any]]:
    """The outcome of a run whose process died without a word (``exitcode`` < 0: killed by
    that signal, e.g. -9 from the kernel's OOM killer)."""
    k, _spec, out = job[:3]
    how = (f"killed by signal {-exitcode}" + (" (SIGKILL: the kernel's OOM killer, or kill "
           "-9)" if exitcode == -9 else "") if exitcode < 0 else f"exit code {exitcode}")
    return k, {"action": RunAction.FAILED, "seconds": 0.0,
               "error": f"the training process died ({how}); its last checkpoint in {out} "
                        "is kept: run the sweep again to resume it"}


def _describe(err: BaseException) -> str:
    return f"{type(err).__name__}: {err}"


def read_run_files(run_dir: str | os.PathLike[str]) -> dict[str, bytes]:
    """Every file of a run directory (relative posix path -> bytes), without the
    temporary files of interrupted atomic writes; ``{}`` if the folder does not exist."""
    root = Path(run_dir)
    if not root.is_dir():
        return {}
    files = {}
    for p in sorted(root.rglob("*")):
        if p.is_file() and not (p.name.startswith(".") and p.name.endswith(".tmp")):
            files[p.relative_to(root).as_posix()] = p.read_bytes()
    return files


def _write_order(name: str) -> tuple[int, str]:
    # config first, result.json last: an interrupted write-back leaves an unfinished run
    # (metrics rows past the latest checkpoint are dropped on resume)
    rank = {CONFIG_FILE: 0, LATEST_FILE: 1, METRICS_FILE: 2, RESULT_FILE: 4}
    return rank.get(name, 3), name


def write_run_files(run_dir: str | os.PathLike[str], files: Mapping[str, bytes],
                    sent: Iterable[str] = ()) -> None:
    """Write ``files`` (relative path -> bytes) into ``run_dir``, each atomically and
    ``result.json`` last; files in ``sent`` (those the task was given) that the task no
    longer has are removed first. Unchanged files are not rewritten."""
    root = Path(run_dir)
    for name in sent:
        if name not in files:
            (root / name).unlink(missing_ok=True)
    for name in sorted(files, key=_write_order):
        rel = Path(name)
        if rel.is_absolute() or ".." in rel.parts:
            raise InputError(f"refusing to write {name!r} outside the run directory")
        target = root / rel
        if target.is_file() and target.read_bytes() == files[name]:
            continue
        atomic_write_bytes(target, files[name])


def _run_remote(spec: RunSpec, files: dict[str, bytes], timesteps: int | None,
                minutes: float | None, overrides: dict[str, Any],
                modules: tuple[str, ...] = ()) -> dict[str, Any]:
    """Ray-task body: rebuild the run directory from ``files`` in a temporary folder, make
    sure the run is finished there, and return its files (also after a failure, so that
    the progress made is kept and resumed next time)."""
    with tempfile.TemporaryDirectory(prefix="geodesics-sweep-") as tmp:
        run_dir = Path(tmp) / "run"
        if files:
            write_run_files(run_dir, files)
        out = _run_local(spec, str(run_dir), timesteps, minutes, overrides, modules)
        out["files"] = read_run_files(run_dir)
        out["node"] = os.uname().nodename
    return out


# ----------------------------------------------------------------------------------------
# Ray
# ----------------------------------------------------------------------------------------
def _prepare(spec: RunSpec, out: Path) -> None:
    """A run stopped before its first checkpoint cannot be resumed: clear it so it starts
    afresh (it holds only its config and at most a metrics header)."""
    path = spec.path(out)
    if run_status(path) is RunStatus.UNFINISHED and not (path / LATEST_FILE).is_file():
        for p in path.iterdir():
            if p.is_file():
                p.unlink()


# ----------------------------------------------------------------------------------------
# the sweep
# ----------------------------------------------------------------------------------------
def run_sweep(plan: SweepPlan, out: str | os.PathLike[str], workers: int | None = None,
              ray_address: str | None = None, progress: bool = True,
              on_done: Callable[[RunOutcome], None] | None = None) -> SweepResult:
    """Make every run of ``plan`` finished in ``out`` (see the module docstring).

    ``workers``: local processes (default ``min(2, runs to do)``), or with Ray the
    largest number of tasks in flight (default: all, the cluster schedules them). One run
    failing (an exception) does not stop the others: it is reported as ``failed`` with
    its error in the result and ``sweep.json``. ``on_done`` is called with each outcome
    as it completes.
    """
    from tqdm.auto import tqdm

    t0 = time.perf_counter()
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, int)
                                or workers < 1):
        raise InputError(f"workers must be a positive integer, got {workers!r}")
    root = Path(out)
    if root.exists() and not root.is_dir():
        raise InputError(f"--out {root} exists and is not a folder")
    check_existing(plan, root)
    outcomes = [RunOutcome(s) for s in plan.runs()]
    todo = []
    for o in outcomes:
        if run_status(o.spec.path(root)) is RunStatus.FINISHED:
            res = run_one(o.spec.env, o.spec.variant, o.spec.seed, o.spec.path(root))
            o.action, o.result = RunAction(res.pop("action")), res
        else:
            todo.append(o)
    backend = {"backend": "ray" if ray_address else "local", "ray": ray_address,
               "workers": workers}
    started_ray = False
    if ray_address is not None and todo:
        started_ray = connect_ray(ray_address, num_cpus=workers or min(2, max(len(todo), 1)))
    root.mkdir(parents=True, exist_ok=True)
    _write_sweep_json(root, plan, backend, outcomes)
    bar = tqdm(total=len(outcomes), initial=len(outcomes) - len(todo), unit="run",
               desc="sweep", disable=not progress, dynamic_ncols=True)

    def done(o: RunOutcome, res: dict[str, Any]) -> None:
        o.action, o.seconds = RunAction(res["action"]), float(res.get("seconds", 0.0))
        o.error = res.get("error")
        o.result = res.get("result")
        _write_sweep_json(root, plan, backend, outcomes)
        bar.update(1)
        bar.set_postfix_str(f"{o.spec.rel_dir} {o.action}")
        if on_done is not None:
            on_done(o)

    for o in todo:
        _prepare(o.spec, root)
    try:
        if todo and ray_address is not None:
            _sweep_ray(plan, root, todo, workers, done)
        elif todo:
            _sweep_local(plan, root, todo, workers or min(2, len(todo)), done)
    finally:
        bar.close()
        if started_ray:
            import ray

            ray.shutdown()
        _write_sweep_json(root, plan, backend, outcomes)
    return SweepResult(plan, root, backend["backend"], outcomes, time.perf_counter() - t0)


def _run_local_job(job: tuple) -> tuple[int, dict[str, Any]]:
    k, *args = job
    return k, _run_local(*args)


def _sweep_local(plan: SweepPlan, root: Path, todo: list[RunOutcome], workers: int,
                 done: Callable[[RunOutcome, dict[str, Any]], None]) -> None:
    from finsler.infra.pool import ProcessPool

    jobs = [(k, o.spec, str(o.spec.path(root)), plan.timesteps, plan.minutes,
             dict(plan.overrides.get(o.spec.variant, {})), plan.modules)
            for k, o in enumerate(todo)]
    # SIGINT / SIGTERM: every worker gets SIGTERM, saves a resumable checkpoint and exits;
    # finsler.infra.pool.PoolInterrupted is raised once they are gone
    # a run whose process dies (OOM killer, segfault) is reported failed; the others go on
    with ProcessPool(workers, initializer=_set_threads, graceful=True,
                     on_death=_died) as pool:
        for k, res in pool.map_unordered(_run_local_job, jobs):
            done(todo[k], res)


def _sweep_ray(plan: SweepPlan, root: Path, todo: list[RunOutcome], workers: int | None,
               done: Callable[[RunOutcome, dict[str, Any]], None]) -> None:
    import ray

    task = ray.remote(num_cpus=1, max_retries=0)(_run_remote)
    queue = list(todo)
    running: dict[Any, tuple[RunOutcome, list[str]]] = {}
    limit = workers or len(todo)
    try:
        while queue or running:
            while queue and len(running) < limit:
                o = queue.pop(0)
                files = read_run_files(o.spec.path(root))
                ref = task.remote(o.spec, files, plan.timesteps, plan.minutes,
                                  dict(plan.overrides.get(o.spec.variant, {})), plan.modules)
                running[ref] = (o, list(files))
            ready, _ = ray.wait(list(running), num_returns=1)
            o, sent = running.pop(ready[0])
            try:
                res = ray.get(ready[0])
            except Exception as err:  # the task or its worker died
                res = {"action": RunAction.FAILED,
                       "error": f"Ray task failed: {_describe(err)}"}
            if res.get("files"):
                write_run_files(o.spec.path(root), res.pop("files"), sent)
            done(o, res)
    except BaseException:
        for ref in running:
            ray.cancel(ref, force=True)
        raise
