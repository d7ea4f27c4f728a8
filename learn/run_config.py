"""The fields every learning run has, declared and checked once: `RunConfig`.

Every method's config is a dataclass on `RunConfig` (the midpoint learner's
[`learn.TrainConfig`][learn.TrainConfig], `learn.pg.PGConfig`, `learn.seq.SeqConfig`, the
shipped example `learn.examples.toy_method.ToyConfig`, a method of your own). The
base holds the run's metric (``env``, ``metric_params``, ``metric_class``) and its run
control (``method``, ``seed``, ``timesteps``, ``minutes``, ``device``, ``threads``,
``depth``, ``eps``, ``eval_every``, ``eval_pairs``) and checks them, one way, when a config
is built. A method adds its own fields and says only what differs for it:

* ``config_methods``: the values its ``method`` field may take (the first is the default);
* ``run_defaults``: other defaults of the base's fields (e.g. ``{"eval_every": 10}``); a
  method never declares a base field again (that is an error when its class is made);
* `RunConfig.validate`: the checks of its own fields, and `RunConfig.complete`
  for fields filled in from others (PG's schedule fills ``timesteps``).

Configs also come from JSON files and ``--set FIELD=VALUE``, so `RunConfig.check_types`
checks the type of every field annotated ``str``, ``int``, ``float``, ``bool`` or
``tuple[int, ...]`` (each maybe ``| None``) for every method.

The module also holds what a run directory says about its metric and software
(`run_header`, `metric_info`, `package_versions`) and the check that a
loaded run is on the metric asked for (`check_run_metric`). It imports nothing of
`learn`: the run loop (`learn.loop`) stands on it, below every method.
"""

from __future__ import annotations

import dataclasses
import inspect
import itertools
import math
import platform
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, TypeVar

import finsler
from finsler.errors import InputError
from finsler.infra.limits import check_memory
from finsler.metrics.base import TrainingSettings
from finsler.spec import MetricSpec, class_path, ensure_registered

__all__ = [
    "RUN_FIELDS",
    "RunConfig",
    "build_metric",
    "check_choice",
    "check_hidden",
    "check_run_metric",
    "ensure_registered",
    "metric_class_path",
    "metric_info",
    "package_versions",
    "resolve_metric",
    "run_header",
    "training_settings",
]

_C = TypeVar("_C", bound="RunConfig")
_KINDS = {"str": (str,), "int": (int,), "float": (int, float), "bool": (bool,)}


def check_choice(name: str, value: str, allowed: tuple[str, ...]) -> None:
    """Raise `InputError` unless ``value`` is one of ``allowed``."""
    if value not in allowed:
        raise InputError(f"{name} must be one of {', '.join(allowed)}; got {value!r}")


def check_hidden(hidden: tuple[int, ...], dim: int = 8, name: str = "hidden") -> None:
    """Raise `InputError` unless ``hidden`` (the config field ``name``) are positive
    layer widths whose MLPs (inputs ~ ``2 * dim`` + a few) fit in memory
    (`finsler.infra.limits.check_memory`, before any network is built)."""
    if not hidden or any(h < 1 for h in hidden):
        raise InputError(f"{name} sizes must be positive, got {hidden!r}")
    widths = [2 * dim + 4, *hidden, 2 * dim]
    weights = sum((a + 1) * b for a, b in itertools.pairwise(widths))
    check_memory((weights,), f"{name} {list(hidden)} (about {weights:.3g} weights per "
                 "network)", hint="choose smaller layers", itemsize=4, copies=4)


def _positive_int(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise InputError(f"{name} must be a positive integer, got {value!r}")


def _positive_finite(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            0 < value < math.inf):
        raise InputError(f"{name} must be positive and finite, got {value!r}")


# ----------------------------------------------------------------------------------------
# The run's metric: registered name + parameters (+ the class of a user metric). Its
# identity is finsler's (finsler.MetricSpec).
# ----------------------------------------------------------------------------------------
#: ``module:qualname`` of a metric class defined outside `finsler` (None for the
#: toolkit's own metrics): `finsler.spec.class_path`.
metric_class_path = class_path


def resolve_metric(env: str, params: Any = None,
                   metric_class: str | None = None) -> tuple[dict[str, Any], str | None]:
    """Check a run's metric and return ``(full parameters, class path)``: the parts of
    `finsler.MetricSpec.resolve` (unknown names and ill-typed values raise
    `InputError` naming the allowed parameters; a user metric's module is imported
    from ``metric_class`` if ``env`` is not registered)."""
    spec = MetricSpec.resolve(env, params, metric_class)
    return dict(spec.params), spec.class_path


def build_metric(env: str, params: dict[str, Any] | None = None) -> finsler.Metric:
    """The registered metric ``env`` with ``params`` (`finsler.MetricSpec.build`)."""
    return MetricSpec(env, dict(params or {})).build()


# ----------------------------------------------------------------------------------------
# The config every method extends
# ----------------------------------------------------------------------------------------
@dataclass
class RunConfig:
    """The fields every learning run has (see the module docstring): a method's config
    subclasses it with ``@dataclass``, sets ``config_methods`` and, where its defaults
    differ, ``run_defaults``, and adds its own fields after these."""

    env: str = "matsumoto"
    """Registered metric name (``finsler.list_metrics()``)."""
    metric_params: dict[str, Any] | None = None
    """Parameters of the metric (``finsler.get_metric(env, **metric_params)``); None or {}
    = its defaults. Completed to the full parameter set when the config is built."""
    metric_class: str | None = None
    """``module:qualname`` of a metric class registered outside the toolkit (filled in
    automatically; re-imported when the run is loaded in another process)."""
    method: str = ""
    """The method's name in `learn.registry` (one of the config's
    ``config_methods``; the first is the default)."""
    seed: int = 0
    """Seed of the run's generators and of the network initialisation (>= 0)."""
    timesteps: int | None = 20_000_000
    """Budget of evaluations of C (all-inclusive: every evaluation the method makes to
    learn, counted by the method). None only where the method fills it in (PG: its
    schedule's total)."""
    minutes: float | None = None
    """Optional wall-clock limit (cumulative across resumes); training stops at whichever
    limit comes first. Positive and finite."""
    device: str = "cpu"
    """``cpu``, ``cuda`` or ``cuda:N``."""
    threads: int = 1
    """torch intra-op threads (1 keeps runs bit-reproducible and leaves cores free)."""
    depth: int | None = None
    """Tree depth D of evaluation (``2**D`` segments); None = the task's depth."""
    eps: float | None = None
    """Success threshold of the logged evaluations; None = the task's."""
    eval_every: int = 10
    """Between two evaluations on the validation pair set (each also writes the latest
    checkpoint), in the method's unit: iterations, or (Seq) all-inclusive timesteps."""
    eval_pairs: int = 100
    """Size of the validation set (``finsler.validation_pairs``: its own seed, distinct
    from the default evaluation set) on which ``checkpoint_best`` is chosen."""

    config_methods: ClassVar[tuple[str, ...]] = ()
    """The values of ``method`` a config class trains (the first is the default)."""
    run_defaults: ClassVar[Mapping[str, Any]] = {}
    """Defaults of the fields above that differ for a method (its class's own; a subclass
    of it inherits them)."""

    def __init_subclass__(cls, **kwargs: Any) -> None:
        """Give the base's fields the subclass's defaults (``run_defaults``, ``method`` =
        ``config_methods[0]``) without declaring them again; declaring one again is a
        `TypeError` (they are declared and checked here only)."""
        super().__init_subclass__(**kwargs)
        own = dict(inspect.get_annotations(cls))
        again = sorted(set(own) & set(RUN_FIELDS))
        if again:
            raise TypeError(f"{cls.__name__} declares the run field(s) {', '.join(again)} "
                            "again; set their defaults in run_defaults instead")
        defaults = dict(cls.__dict__.get("run_defaults", {}))
        methods = cls.__dict__.get("config_methods")
        if methods and "method" not in defaults:
            defaults["method"] = methods[0]
        unknown = sorted(set(defaults) - set(RUN_FIELDS))
        if unknown:
            raise TypeError(f"{cls.__name__}.run_defaults: {', '.join(unknown)} are not "
                            f"fields of RunConfig ({', '.join(RUN_FIELDS)})")
        if defaults:
            # the same field, in the same place, with the method's default (a dataclass
            # keeps an inherited field's position when a subclass annotates it)
            cls.__annotations__ = {**own, **{k: RUN_FIELDS[k] for k in defaults}}
            for name, value in defaults.items():
                setattr(cls, name, value)

    def __post_init__(self) -> None:
        self.check_types()
        self.check_run()
        self.validate()
        self.complete()
        if self.timesteps is None:
            raise InputError("timesteps must be a positive integer, got None")

    # -- the checks -----------------------------------------------------------------------
    def check_types(self) -> None:
        """Raise `InputError` naming the first field of the wrong type (fields
        annotated ``str``, ``int``, ``float``, ``bool``, ``tuple[int, ...]``, each maybe
        ``| None``, with or without ``from __future__ import annotations``; fields of other
        types are left to the config's own checks). A ``tuple[int, ...]`` given as a list
        (JSON) becomes a tuple. Then the metric is resolved: ``metric_params`` completed
        to the full set, ``metric_class`` filled in."""
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            ann = f.type.__name__ if isinstance(f.type, type) else str(f.type)
            if ann.endswith(" | None"):
                if v is None:
                    continue
                ann = ann[: -len(" | None")]
            if ann == "tuple[int, ...]":
                ok = isinstance(v, (tuple, list)) and all(
                    isinstance(h, int) and not isinstance(h, bool) for h in v)
                if ok and isinstance(v, list):
                    setattr(self, f.name, tuple(v))
            elif ann in _KINDS:
                ok = isinstance(v, _KINDS[ann]) and (ann == "bool" or not isinstance(v, bool))
            else:
                continue
            if not ok:
                raise InputError(f"config field {f.name} must be {ann}, got {v!r}")
        self.metric_params, self.metric_class = resolve_metric(
            self.env, self.metric_params, self.metric_class)

    def check_run(self) -> None:
        """Raise `InputError` naming the first impossible run field (after
        `check_types`): every method's run fields are checked here, the same way."""
        finsler.registry.check_name(self.env, "environment")
        if self.config_methods:
            check_choice("method", self.method, self.config_methods)
        elif not self.method:
            raise InputError("method must name the method (config_methods is empty)")
        if self.seed < 0:
            raise InputError(f"seed must be a non-negative integer, got {self.seed!r}")
        for name in ("threads", "eval_every", "eval_pairs"):
            _positive_int(name, getattr(self, name))
        if self.timesteps is not None:
            _positive_int("timesteps", self.timesteps)
        if self.depth is not None:
            _positive_int("depth", self.depth)
        for name in ("minutes", "eps"):
            if getattr(self, name) is not None:
                _positive_finite(name, getattr(self, name))
        if self.device not in ("cpu", "cuda") and not self.device.startswith("cuda:"):
            raise InputError(f"device must be 'cpu' or 'cuda', got {self.device!r}")

    def validate(self) -> None:
        """The method's checks of its own fields (raise `InputError` naming the
        first impossible one); the run fields are checked already."""

    def complete(self) -> None:
        """Fill in fields derived from others (after `validate`)."""

    # -- what the config gives ------------------------------------------------------------
    @property
    def metric_spec(self) -> MetricSpec:
        """The run's metric as a [`finsler.MetricSpec`][finsler.MetricSpec]."""
        return MetricSpec(self.env, dict(self.metric_params or {}), self.metric_class)

    @property
    def metric(self) -> finsler.Metric:
        """The run's metric: ``env`` with ``metric_params``."""
        return self.metric_spec.build()

    @property
    def max_depth(self) -> int:
        """The tree depth D of evaluation (``depth`` or the task's)."""
        return int(self.depth if self.depth is not None else self.metric.task.depth)

    @property
    def eval_eps(self) -> float:
        """The success threshold of evaluation (``eps`` or the task's)."""
        return float(self.eps if self.eps is not None else self.metric.task.eps)

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
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
        names = {f.name for f in dataclasses.fields(self)}
        unknown = sorted(set(changes) - names)
        if unknown:
            raise InputError(f"unknown config field(s) of {type(self).__name__}: "
                             f"{', '.join(unknown)}")
        return dataclasses.replace(self, **changes)


#: The fields of [`RunConfig`][learn.run_config.RunConfig] and their annotations (the run fields).
RUN_FIELDS: dict[str, Any] = {f.name: f.type for f in dataclasses.fields(RunConfig)}


# ----------------------------------------------------------------------------------------
# What a run directory says about its metric and software
# ----------------------------------------------------------------------------------------
def metric_info(cfg: Any) -> dict[str, Any]:
    """``config.json``'s ``metric`` section: `finsler.Metric.info` plus the full
    parameters and, for a user metric, its class (``module:qualname``)."""
    return {**cfg.metric.info(), "params": dict(cfg.metric_params or {}),
            "class": cfg.metric_class}


def check_run_metric(cfg: Any, source: str, env: str | None = None,
                     metric_params: dict[str, Any] | None = None) -> None:
    """Raise `InputError` unless the run ``cfg`` (loaded from ``source``) is on
    metric ``env`` (if given) with ``metric_params`` (if given; compared after completing
    them to the full set, so ``{"a": 0.2}`` equals the run's ``{"a": 0.2}`` and unnamed
    parameters must have their defaults)."""
    if env is not None and env != cfg.env:
        raise InputError(f"--env {env} does not match the run's environment {cfg.env}")
    if metric_params is None:
        return
    given = MetricSpec.resolve(cfg.env, metric_params, cfg.metric_class)
    diff = cfg.metric_spec.param_differences(given)
    if diff:
        text = ", ".join(f"{k}={a!r} (given {b!r})" for k, (a, b) in diff.items())
        raise InputError(f"{source} was trained on {cfg.env} with other metric parameters: "
                         f"{text}; a policy is only loaded for the metric it learned")


def package_versions() -> dict[str, str]:
    """Versions of python, torch, numpy, casadi (recorded in every run's config)."""
    import casadi
    import numpy
    import torch

    return {
        "python": platform.python_version(),
        "torch": torch.__version__,
        "numpy": numpy.__version__,
        "casadi": casadi.__version__,
    }


def run_header(cfg: Any) -> dict[str, Any]:
    """The first sections of every run's ``config.json``: the config, the metric (with its
    full parameters) and the task (depth, eps, segments)."""
    return {"config": cfg.to_dict(), "metric": metric_info(cfg),
            "task": {"depth": cfg.max_depth, "eps": cfg.eval_eps,
                     "segments": 2**cfg.max_depth}}


def training_settings(env: str) -> TrainingSettings:
    """What the metric registered as ``env`` declares for learning (``Metric.training``:
    the paper's learning rate and budget, the measured defaults, the model-free
    overrides); an unregistered name gets the base's (the paper's Matsumoto settings)."""
    if env in finsler.list_metrics():
        return finsler.metric_class(env).training
    return TrainingSettings()
