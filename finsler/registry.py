"""Registry of metrics by name: ``get_metric(name, **params)``, ``list_metrics()``,
``metric_class(name)``. A metric's identity (name or class, parameters) turned into a spec
and back lives beside it, in `finsler.spec`."""

from __future__ import annotations

import dataclasses
import difflib
import threading
from collections import OrderedDict
from typing import Any

from finsler.errors import InputError, UnknownMetricError, short
from finsler.metrics.base import Metric
from finsler.metrics.checks import check_params
from finsler.metrics.closed_form import (
    Euclidean,
    Minkowski,
    Poincare,
    PoincareSlab,
    Randers,
    Sphere,
)
from finsler.metrics.paper import CarLike, Matsumoto, PandaPole

__all__ = ["check_name", "get_metric", "list_metrics", "metric_class", "register_metric",
           "shared_instance", "unregister_metric"]

_REGISTRY: dict[str, type[Metric]] = {}


def register_metric(cls: type[Metric]) -> type[Metric]:
    """Register a metric class (a frozen dataclass subclass of `Metric`) by its
    ``name``. Usable as a decorator; re-registering a name replaces it."""
    if not (isinstance(cls, type) and issubclass(cls, Metric) and dataclasses.is_dataclass(cls)):
        raise InputError("register_metric needs a dataclass subclass of finsler.Metric")
    _REGISTRY[cls.name] = cls
    return cls


for _cls in (Matsumoto, CarLike, PandaPole, Euclidean, Minkowski, Randers, Poincare, Sphere,
             PoincareSlab):
    register_metric(_cls)


def unregister_metric(name: str) -> type[Metric] | None:
    """Remove the metric registered as ``name`` (returns its class; None if there was
    none), e.g. to undo a registration in a test."""
    return _REGISTRY.pop(name, None)


def metric_class(name: str) -> type[Metric]:
    """The class registered as ``name`` (`UnknownMetricError` with a did-you-mean
    otherwise)."""
    return _REGISTRY[check_name(name)]


def list_metrics(*, provides: str | None = None, dim: int | None = None,
                 convex_everywhere: bool | None = None) -> list[str]:
    """Names of the registered metrics, in registration order; the keywords keep those whose
    default-parameter instance answers as asked: ``provides`` a hook (e.g. ``"distance"``:
    a closed form, `finsler.hooks`), has dimension ``dim``, is strongly convex on its
    whole domain (``convex_everywhere``). Code that needs "the metrics with a closed form"
    asks here instead of keeping a list of names."""
    names = list(_REGISTRY)
    if provides is None and dim is None and convex_everywhere is None:
        return names
    out = []
    for name in names:
        m = get_metric(name)
        if provides is not None and not m.provides(provides):
            continue
        if dim is not None and m.dim != dim:
            continue
        if convex_everywhere is not None and bool(m.convex_everywhere) != convex_everywhere:
            continue
        out.append(name)
    return out


def check_name(name: str, what: str = "metric") -> str:
    """``name`` if a metric is registered under it; otherwise `UnknownMetricError`
    naming the closest registered name (``what``: how the caller calls it, e.g.
    ``environment``)."""
    if not isinstance(name, str):
        raise UnknownMetricError(f"{what} must be a registered metric name (str), got "
                                 f"{type(name).__name__} {short(repr(name), 80)}")
    if name in _REGISTRY:
        return name
    lower = {k.lower(): k for k in _REGISTRY}
    close = ([lower[str(name).lower()]] if str(name).lower() in lower
             else difflib.get_close_matches(str(name), _REGISTRY, n=1))
    hint = f" (did you mean {close[0]!r}?)" if close else ""
    raise UnknownMetricError(f"unknown {what} {short(name, 80)!r}{hint}; registered: "
                             f"{', '.join(_REGISTRY)}")


def get_metric(name: str, /, **params: Any) -> Metric:
    """The metric registered as ``name`` with its parameters overridden by ``params``.

    Raises `UnknownMetricError` for an unknown name or parameter and `InputError` for a
    parameter value of the wrong type (checked against the class's field annotations, as
    a `MetricSpec` checks them) or one the metric refuses.
    """
    if isinstance(name, Metric):
        if params:
            raise InputError("parameters can only be given with a metric name")
        return name
    check_name(name)
    cls = _REGISTRY[name]
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(params) - fields)
    if unknown:
        raise UnknownMetricError(
            f"metric {name!r} has no parameter {', '.join(map(repr, unknown))}; "
            f"its parameters are: {', '.join(sorted(fields)) or '(none)'}"
        )

    checked = check_params(name, cls, params)
    try:
        return shared_instance(cls, checked)
    except InputError:
        raise
    except (TypeError, ValueError, ArithmeticError) as err:  # a metric's own check
        raise InputError(f"metric {name!r} refuses parameters {short(repr(params), 80)}: "
                         f"{short(str(err), 120)}") from err


#: How many (class, parameters) instances `shared_instance` keeps.
SHARED_INSTANCES = 128

_SHARED: OrderedDict[tuple, Metric] = OrderedDict()
_SHARED_LOCK = threading.Lock()


def shared_instance(cls: type[Metric], params: dict[str, Any]) -> Metric:
    """``cls(**params)``, the same object for the same class and full parameter set (the
    last `SHARED_INSTANCES` of them): metrics are frozen, and what they derive
    (lowered programs, NLPs, the spray: `Metric.derived`) lives on the instance, so a
    metric asked for again, by name or by spec, reuses it instead of building it again.
    A metric with unhashable parameter values is not shared."""
    metric = cls(**params)
    key = (cls, tuple((f.name, type(v).__name__, v) for f in dataclasses.fields(metric)
                      for v in (getattr(metric, f.name),)))
    try:
        hash(key)
    except TypeError:
        return metric
    with _SHARED_LOCK:
        shared = _SHARED.setdefault(key, metric)
        _SHARED.move_to_end(key)
        while len(_SHARED) > SHARED_INSTANCES:
            _SHARED.popitem(last=False)
    return shared
