"""One entry point for every learning method: named variants, training, status, loading.

Every method (the midpoint learner of `learn.midpoint.trainer`, the paper's baselines
`learn.seq.trainer` and `learn.pg.trainer`, and any method registered from a user's file)
writes run directories of the same layout (``config.json``, ``metrics.csv``,
``checkpoint_latest.pt``, ``checkpoint_best.pt`` and, once finished, ``result.json``:
[`learn.loop.RunLoop`][learn.loop.RunLoop]). This module finds a run's method in `learn.registry`,
so that the CLI, sweeps and reports never branch on it themselves.

Variants (`VARIANTS`, read from the registry) are the configurations compared in the
paper's experiment:

* ``midpoint``: the toolkit's defaults ([`learn.default_config`][learn.default_config]); for some
  environments they differentiate C (the path-energy term): not model-free;
* ``midpoint-free``: the model-free defaults: every term that uses the derivative of C
  switched off (values of C only, like the paper's method), with the passes per collection
  Algorithm 1 alone was measured best with (``learn.midpoint.config.model_free_overrides``);
* ``paper``: appendix B.1's settings (`learn.paper_config`);
* ``inter`` / ``two-to-one``: ``midpoint-free`` with the actor loss of eq. (17) / (18);
* ``seq``: goal-conditioned PPO (section 5.2, appendix B.2);
* ``pg``: per-depth policy gradient (section 5.2, appendix B.3);
* and the variants of every method registered with `learn.registry.register_method`.
"""

from __future__ import annotations

import contextlib
import os
import shutil
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any

from finsler.errors import InputError, short
from finsler.infra.files import check_path_text
from finsler.status import RunAction, RunStatus
from learn.loop import read_config_section, shipped_dir, shipped_policies
from learn.registry import find_variant, get_method, method_of_run, variants
from learn.storage import (
    BEST_FILE,
    CONFIG_FILE,
    LATEST_FILE,
    METRICS_FILE,
    RESULT_FILE,
    read_json,
)

__all__ = [
    "VARIANTS",
    "load_any_policy",
    "load_policy",
    "load_run_config",
    "make_config",
    "run_lock",
    "run_one",
    "run_status",
    "train_run",
    "warm_start_paths",
]


class _Variants(Mapping[str, str]):
    """Variant name -> summary, read from `learn.registry` (live: a method
    registered later appears)."""

    def __getitem__(self, name: str) -> str:
        return variants()[name].summary

    def __iter__(self) -> Iterator[str]:
        return iter(variants())

    def __len__(self) -> int:
        return len(variants())

    def __repr__(self) -> str:
        return repr(dict(self))


VARIANTS: Mapping[str, str] = _Variants()


def make_config(env: str, variant: str, seed: int = 0, timesteps: int | None = None,
                minutes: float | None = None, device: str = "cpu",
                **overrides: Any) -> Any:
    """The config of ``variant`` (a key of `VARIANTS`) for ``env``; ``timesteps`` and
    ``minutes`` bound the run (all-inclusive evaluations of C / wall minutes)."""
    _, var = find_variant(variant)
    common: dict[str, Any] = {"seed": seed, "minutes": minutes, "device": device}
    if timesteps is not None:
        common["timesteps"] = timesteps
    common.update(overrides)
    return var.make(env, **common)


def load_run_config(run_dir: str | Path) -> Any:
    """The config saved in a run directory, as the method's config class."""
    if not Path(run_dir).is_dir():
        raise InputError(f"run directory {run_dir} does not exist")
    section = read_config_section(run_dir)
    return method_of_run(run_dir, section).config_class.from_dict(section)


def train_run(cfg: Any, out: str | Path, resume: bool = False, progress: bool = True) -> Any:
    """Train ``cfg`` (any method's config) into run directory ``out``."""
    return get_method(cfg.method).train(cfg, out, resume=resume, progress=progress)


def load_any_policy(run: str | Path, checkpoint: str = "best", device: str = "cpu",
                    env: str | None = None,
                    metric_params: dict[str, Any] | None = None) -> Any:
    """Load the policy of any method from a run directory (or a shipped policy's name):
    `learn.load_policy`. ``env`` and ``metric_params``, if given, must be the run's
    metric and parameters (the run's own parameters are always used: a policy is loaded
    for the metric it learned)."""
    return load_policy(run, device=device, checkpoint=checkpoint, env=env,
                       metric_params=metric_params)


def load_policy(run: str | Path, device: str = "cpu", checkpoint: str = "best",
                env: str | None = None, metric_params: dict[str, Any] | None = None) -> Any:
    """Load the policy of any learning method from a run directory (the method's loader,
    found in `learn.registry` by the run's ``method``), or, given an environment
    name, the midpoint policy shipped with the package. ``checkpoint``: ``best`` (best
    success on the validation set during training; falls back to the latest) or
    ``latest``; the policy's ``checkpoint`` attribute names the file actually loaded.
    With ``env``, the policy must belong to that environment; with ``metric_params``, to
    the metric with those parameters (the run's config records them; runs written before
    the field existed are on the defaults). A user metric's class is re-imported from the
    config's ``metric_class``, a user method's module from ``method_module``, if they are
    not registered.

    Raises `InputError` for a missing directory, an unknown name, an ``env`` or
    parameter mismatch, and `CorruptFileError` for unreadable files.
    """
    path = check_path_text(run, "run (a run directory or a shipped policy's name)")
    for name, value in (("checkpoint", checkpoint), ("device", device)):
        if not isinstance(value, str):
            raise InputError(f"{name} must be a str, got {type(value).__name__} "
                             f"{short(repr(value), 80)}")
    if env is not None and not isinstance(env, str):
        raise InputError(f"env must be a metric name (str) or None, got {type(env).__name__} "
                         f"{short(repr(env), 80)}")
    if metric_params is not None and not isinstance(metric_params, dict):
        raise InputError(f"metric_params must be a dict or None, got "
                         f"{type(metric_params).__name__} {short(repr(metric_params), 80)}")
    if path.is_dir():
        method = method_of_run(path, read_config_section(path))
        return method.load_policy(path, checkpoint=checkpoint, device=device, env=env,
                                  metric_params=metric_params)
    if str(run) in shipped_policies():
        path = shipped_dir(str(run))
        method = method_of_run(path, read_config_section(path))
        return method.load_policy(path, checkpoint=checkpoint, device=device, env=env,
                                  metric_params=metric_params)
    known = ", ".join(shipped_policies()) or "none"
    raise InputError(f"run directory {short(str(run), 80)!r} does not exist and is not the "
                     f"name of a shipped policy (shipped: {known})")


def warm_start_paths(source: str | Path, metric: Any, pairs: Any,
                     checkpoint: str = "best", search: bool = False) -> tuple[Any, Any]:
    """Learned paths to seed exact solves: ``(paths (K, 2**D + 1, dim) float64, policy)``.

    ``source`` is a run directory (any method) or the name of an environment with a shipped
    policy; ``metric`` (a [`finsler.Metric`][finsler.Metric]) is the metric of the solve and must be
    the policy's: the same registered metric with the same parameters, else
    `InputError` naming the difference. ``pairs`` ``(K, 2, dim)``. ``search``: the
    route search's paths (`learn.Policy.search`) instead of the plain generation.
    """
    from finsler import MetricSpec

    src = str(source)
    path = Path(source)
    if path.is_dir():
        pol = load_any_policy(path, checkpoint=checkpoint)
    elif src in shipped_policies():
        pol = load_policy(src, checkpoint=checkpoint)
    else:
        import finsler

        known = ", ".join(shipped_policies()) or "none"
        if src in finsler.list_metrics():
            raise InputError(f"--warm-start {src}: no shipped policy for {src!r} (shipped: "
                             f"{known}); train one with `geodesics train` and pass its run "
                             "directory")
        raise InputError(f"--warm-start {src}: no such run directory, and not an environment "
                         f"with a shipped policy (shipped: {known})")
    mine, theirs = MetricSpec.of(pol.metric), MetricSpec.of(metric)
    if mine.name != theirs.name:
        raise InputError(f"--warm-start {src} is a policy for {mine.name!r}, not for "
                         f"{theirs.name!r}")
    if mine != theirs:
        diff = ", ".join(f"{k}={a!r} (solve: {b!r})"
                         for k, (a, b) in sorted(mine.param_differences(theirs).items())) \
            or f"class {mine.class_path} vs {theirs.class_path}"
        raise InputError(f"--warm-start {src} was trained on {mine.name} with other parameters "
                         f"than the solve's metric: {diff}")
    if search:
        if not callable(getattr(pol, "search", None)):
            raise InputError(f"the route search needs a midpoint policy; {src} is a "
                             f"{type(pol).__name__}")
        return pol.search(pairs[:, 0], pairs[:, 1]).paths, pol
    paths = pol.generate(pairs[:, 0], pairs[:, 1])
    return paths, pol


def run_status(out: str | Path) -> RunStatus:
    """``finished`` (result.json present), ``unfinished`` (a resumable checkpoint, no
    result) or ``absent`` (nothing to resume: no run there, or one that stopped before
    its first checkpoint): a `finsler.status.RunStatus` (a ``str`` enum of these
    words)."""
    p = Path(out)
    if (p / RESULT_FILE).is_file():
        return RunStatus.FINISHED
    if (p / CONFIG_FILE).is_file() and (p / LATEST_FILE).is_file():
        return RunStatus.UNFINISHED
    return RunStatus.ABSENT


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


@contextlib.contextmanager
def run_lock(out: str | Path) -> Iterator[None]:
    """Hold ``.<name>.lock`` beside run directory ``out`` while training it, so that two
    sweeps (or a sweep and a user) never train the same run at once on this machine. A
    lock left by a process that no longer exists is taken over."""
    p = Path(out)
    p.parent.mkdir(parents=True, exist_ok=True)
    lock = p.parent / f".{p.name}.lock"
    for _ in range(2):
        try:
            fd = os.open(lock, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            try:
                pid = int(lock.read_text().strip() or "0")
            except (OSError, ValueError):
                pid = 0
            if pid and _alive(pid):
                raise InputError(f"run {p} is being trained by process {pid} (lock {lock})")\
                    from None
            lock.unlink(missing_ok=True)
            continue
        with os.fdopen(fd, "w") as f:
            f.write(str(os.getpid()))
        break
    else:  # pragma: no cover - a third process raced us twice
        raise InputError(f"could not lock run {p} ({lock})")
    try:
        yield
    finally:
        lock.unlink(missing_ok=True)


def _clear_unstarted(out: Path) -> None:
    """Remove what a run that stopped before its first checkpoint left (config, metrics,
    temporary files); anything else in the directory is not ours: refuse."""
    ours = {CONFIG_FILE, METRICS_FILE, BEST_FILE}
    files = list(out.iterdir())
    foreign = [f.name for f in files if f.name not in ours and not f.name.startswith(".")]
    if foreign:
        raise InputError(f"{out} holds files that are not a run's ({', '.join(foreign)}); "
                         "choose another output directory")
    for f in files:
        if f.is_dir():
            shutil.rmtree(f)
        else:
            f.unlink()


def run_one(env: str, variant: str, seed: int, out: str | Path, timesteps: int | None = None,
            minutes: float | None = None, progress: bool = False,
            **overrides: Any) -> dict[str, Any]:
    """Make sure the run ``(env, variant, seed)`` in ``out`` is finished: skip it if it is,
    resume it if it started, start it otherwise. Returns ``result.json``'s content plus
    ``"action"``: a `finsler.status.RunAction`, ``skipped``, ``resumed`` or
    ``started``."""
    cfg = make_config(env, variant, seed=seed, timesteps=timesteps, minutes=minutes,
                      **overrides)
    with run_lock(out):
        status = run_status(out)
        if status is RunStatus.FINISHED:
            return {**read_json(Path(out) / RESULT_FILE), "action": RunAction.SKIPPED}
        if status is RunStatus.ABSENT and Path(out).is_dir():
            _clear_unstarted(Path(out))
        resume = status is RunStatus.UNFINISHED
        train_run(cfg, out, resume=resume, progress=progress)
        return {**read_json(Path(out) / RESULT_FILE),
                "action": RunAction.RESUMED if resume else RunAction.STARTED}
