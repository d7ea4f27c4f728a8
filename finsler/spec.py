"""A metric's identity: its registered name (or its class) and its full parameter set.

The one way, for every package, to turn a metric into a spec and back and to compare two:

* [`MetricSpec.of`][finsler.spec.MetricSpec.of] ``(metric)``: the spec of a metric object;
* `MetricSpec.resolve` ``(name, params, metric_class)``: the spec of a registered name
  with some of its parameters, checked (unknown names and ill-typed values raise
  `InputError` naming the allowed parameters; the metric's own checks run) and
  completed to the FULL parameter set, so that a saved spec pins the metric even if a
  default changes later;
* `MetricSpec.build`: the metric; `MetricSpec.to_dict` /
  [`MetricSpec.from_dict`][finsler.spec.MetricSpec.from_dict]: its JSON form;
* ``spec == other`` and [`MetricSpec.param_differences`][finsler.spec.MetricSpec.param_differences].

A metric class defined outside `finsler` is named by ``module:qualname``
(`class_path`); `ensure_registered` imports that module when the name is not
registered (a run saved in one process, loaded in another). Nothing here imports torch.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from finsler import registry
from finsler.errors import InputError
from finsler.infra.modules import import_user_module
from finsler.metrics.base import Metric
from finsler.metrics.checks import check_params, param_fields

__all__ = ["MetricSpec", "class_path", "ensure_registered", "metric_spec"]

def class_path(cls: type) -> str | None:
    """``module:qualname`` of a metric class defined outside `finsler` (None for the
    toolkit's own metrics)."""
    if cls.__module__ == "finsler" or cls.__module__.startswith("finsler."):
        return None
    return f"{cls.__module__}:{cls.__qualname__}"


def _import_metric_class(name: str, path: str) -> None:
    """Import the module of ``path`` (``module:qualname``) so that metric ``name`` is
    registered (its ``@register_metric`` runs on import; a class found but not registered
    is registered here)."""
    module, sep, qualname = path.partition(":")
    advice = (f"make module {module!r} importable (PYTHONPATH, or `--metric-module "
              f"FILE.py` on the command line) or import it before loading the run")
    if not sep or not module or not qualname:
        raise InputError(f"metric_class must be 'module:qualname', got {path!r}")
    if module == "__main__":
        raise InputError(
            f"metric {name!r} was defined by class {qualname} in a script (__main__), which "
            "cannot be re-imported: register it (run the code defining it) before loading "
            "the run, or move the class into a module")
    try:
        mod = import_user_module(module, f"metric {name!r}: module")
    except InputError as err:
        raise InputError(f"{err}; {advice}") from err
    obj: Any = mod
    for part in qualname.split("."):
        obj = getattr(obj, part, None)
    if not (isinstance(obj, type) and issubclass(obj, Metric)):
        raise InputError(f"metric {name!r}: {path} is not a finsler.Metric class; {advice}")
    if obj.name != name:
        raise InputError(f"metric class {path} is registered as {obj.name!r}, not {name!r}")
    if name not in registry.list_metrics():
        registry.register_metric(obj)


def ensure_registered(name: str, metric_class: str | None = None,
                      what: str = "environment") -> None:
    """Make sure metric ``name`` is registered: import ``metric_class``
    (``module:qualname``) if it is not; `InputError` (with a did-you-mean) if it
    still is not (``what``: how the caller calls the name in that message)."""
    if metric_class is not None and isinstance(name, str) and \
            name not in registry.list_metrics():
        _import_metric_class(name, metric_class)
    registry.check_name(name, what)


def _json_safe(value: Any) -> Any:
    """Tuples to lists, numpy scalars and arrays to Python: the value as it reads back
    from JSON."""
    if isinstance(value, (list, tuple)):
        return [_json_safe(v) for v in value]
    if hasattr(value, "tolist") and not isinstance(value, (str, bytes)):
        return _json_safe(value.tolist())
    return value


@dataclass(frozen=True)
class MetricSpec:
    """A metric's identity: ``name`` (as registered), the FULL parameter set ``params``
    (JSON values: tuples as lists) and, for a class defined outside `finsler`,
    ``class_path`` (``module:qualname``, re-imported where the name is not registered).
    Two specs are equal iff they name the same metric with the same parameters."""

    name: str
    params: Mapping[str, Any]
    class_path: str | None = None
    cls: type[Metric] | None = field(default=None, compare=False, repr=False)
    """The class itself where it is known in this process (a metric object's class, also
    an unregistered one; pickled by reference); not part of the identity or the JSON."""

    def __hash__(self) -> int:
        return hash((self.name, self.class_path,
                     json.dumps(dict(self.params), sort_keys=True, default=repr)))

    # -- metric -> spec -------------------------------------------------------------------
    @classmethod
    def of(cls, metric: Metric) -> MetricSpec:
        """The spec of a metric object (registered or not)."""
        if not isinstance(metric, Metric):
            raise InputError(f"a metric spec needs a finsler.Metric, got {type(metric).__name__}")
        if not dataclasses.is_dataclass(metric):
            raise InputError(f"{type(metric).__name__} is not a dataclass: a metric's "
                             "parameters are its dataclass fields")
        params = {k: _json_safe(getattr(metric, k)) for k in param_fields(type(metric))}
        return cls(metric.name, params, class_path(type(metric)), type(metric))

    @classmethod
    def resolve(cls, name: str, params: Mapping[str, Any] | None = None,
                metric_class: str | None = None, what: str = "environment") -> MetricSpec:
        """The spec of the metric registered as ``name`` with ``params`` (None = its
        defaults), checked and completed to its full parameter set. If ``name`` is not
        registered and ``metric_class`` (``module:qualname``) is given, that module is
        imported first (user metrics); a ``metric_class`` that is not the registered class's
        is an error. Raises [`InputError`][finsler.spec.InputError] naming the problem."""
        if not isinstance(name, str):
            raise InputError(f"{what} must be a registered metric name, got {name!r}")
        if metric_class is not None and not isinstance(metric_class, str):
            raise InputError(f"metric_class must be 'module:qualname', got {metric_class!r}")
        ensure_registered(name, metric_class, what)
        mcls = registry.metric_class(name)
        path = class_path(mcls)
        if metric_class is not None and metric_class != path:
            raise InputError(f"metric {name!r} of this run is class {metric_class}, but {name!r} "
                             f"is registered as {path or mcls.__qualname__ + ' (finsler)'} "
                             "here")
        if params is None:
            params = {}
        if not isinstance(params, Mapping):
            raise InputError(f"metric_params must be a dict of parameter values, got {params!r}")
        fields = param_fields(mcls)
        unknown = sorted(set(params) - set(fields))
        if unknown:
            raise InputError(
                f"metric {name!r} has no parameter {', '.join(map(repr, unknown))}; its "
                f"parameters are: "
                f"{', '.join(f'{k} ({t})' for k, t in fields.items()) or '(none)'}")
        checked = check_params(name, mcls, params)
        metric = cls(name, checked, path, mcls).build()
        return cls.of(metric)

    # -- spec -> metric -------------------------------------------------------------------
    def build(self) -> Metric:
        """The metric (JSON lists become tuples); a metric's own refusal of its parameters
        is an [`InputError`][finsler.spec.InputError]."""
        mcls = self.cls
        if mcls is None:
            ensure_registered(self.name, self.class_path, "metric")
            mcls = registry.metric_class(self.name)
        args = {k: tuple(v) if isinstance(v, list) else v for k, v in self.params.items()}
        try:
            return registry.shared_instance(mcls, args)
        except InputError:
            raise
        except (TypeError, ValueError) as err:  # a metric's own check, not an InputError
            raise InputError(f"metric {self.name!r} refuses parameters {dict(self.params)}: "
                             f"{err}") from err

    # -- JSON -----------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """``{"name", "params", "class"}`` (``class``: ``module:qualname`` or None)."""
        return {"name": self.name, "params": dict(self.params), "class": self.class_path}

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> MetricSpec:
        """The spec of `to_dict`'s form, checked (`resolve`)."""
        if not isinstance(doc, Mapping) or "name" not in doc:
            raise InputError(f"a metric spec is a dict with 'name', 'params', 'class'; got "
                             f"{doc!r}")
        return cls.resolve(doc["name"], doc.get("params"), doc.get("class"), "metric")

    # -- comparison -----------------------------------------------------------------------
    def param_differences(self, other: MetricSpec) -> dict[str, tuple[Any, Any]]:
        """``{parameter: (value here, value in other)}`` for every parameter that differs
        (a parameter one side lacks has the value None there)."""
        keys = list(self.params) + [k for k in other.params if k not in self.params]
        return {k: (self.params.get(k), other.params.get(k)) for k in keys
                if self.params.get(k) != other.params.get(k)}


def metric_spec(metric: Metric | str, params: Mapping[str, Any] | None = None,
                metric_class: str | None = None) -> MetricSpec:
    """`MetricSpec.of` a metric object, or `MetricSpec.resolve` a name."""
    if isinstance(metric, Metric):
        if params is not None or metric_class is not None:
            raise InputError("parameters can only be given with a metric name")
        return MetricSpec.of(metric)
    return MetricSpec.resolve(metric, params, metric_class)
