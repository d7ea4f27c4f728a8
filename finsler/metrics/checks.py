"""Checks of a metric's definition and of the values it is given, behind `finsler.Metric`
and `finsler.spec`: parameter types, a scalar ``F_sx``, sampled values, array kinds."""

from __future__ import annotations

import dataclasses
import functools
import json
import math
import numbers
from collections.abc import Callable, Mapping
from typing import Any

import casadi as ca
import numpy as np

from finsler.domains import Domain, is_torch
from finsler.errors import InputError, short

__all__ = ["check_params", "param_fields"]

#: The field annotations whose values are checked by type (others: any JSON value).
_PARAM_KINDS: dict[str, tuple[type, ...]] = {
    "float": (numbers.Real,), "int": (numbers.Integral,), "bool": (bool, np.bool_),
    "str": (str,)}


#: Points and directions per point of `Metric.check_values`.
VALUE_SAMPLES = (8, 4)


def _value_samples(domain: Domain) -> tuple[np.ndarray, np.ndarray]:
    """``(x, v)``, each ``(N, dim)``: a few points of ``domain`` (uniform, seeded, or the
    projections of points of ``[-1, 1]**dim`` where it cannot be sampled uniformly), each
    with the first coordinate direction, its negative and random unit directions."""
    n, k = VALUE_SAMPLES
    rng = np.random.default_rng(0)
    dim = domain.dim
    try:
        x = np.asarray(domain.sample(n, rng), dtype=float)
    except (InputError, ValueError, TypeError, NotImplementedError):
        x = np.asarray(domain.project(rng.uniform(-1.0, 1.0, (n, dim))), dtype=float)
    g = rng.normal(size=(n, k - 2, dim))
    e = np.zeros((n, 2, dim))
    e[:, 0, 0], e[:, 1, 0] = 1.0, -1.0
    v = np.concatenate([e, g / np.linalg.norm(g, axis=-1, keepdims=True)], axis=1)
    return np.repeat(x, k, axis=0), v.reshape(-1, dim)


def _metric_name(m: Any) -> str:
    return short(str(getattr(m, "name", type(m).__name__)), 80)


#: Field annotations whose values `_check_field_types` checks (others are the metric's own).
_SIMPLE_KINDS = ("float", "int", "bool", "str")


def _check_field_types(metric: Any) -> None:
    """Raise `InputError` naming the parameter if a dataclass field annotated ``float``,
    ``int``, ``bool`` or ``str`` holds a value of another type (``Sphere(radius="abc")``,
    ``radius=True``, ``1 + 1j``, ``height=None``), as `MetricSpec` checks a name's
    parameters. Values are not converted."""
    if not dataclasses.is_dataclass(metric):
        return
    for f in dataclasses.fields(metric):
        kind = f.type if isinstance(f.type, str) else getattr(f.type, "__name__", "")
        if f.init and kind in _SIMPLE_KINDS:
            _check_param(_metric_name(metric), f.name, kind, getattr(metric, f.name))


def _typed_post_init(own: Callable[..., Any]) -> Callable[..., Any]:
    """A metric class's own ``__post_init__`` preceded by `_check_field_types`."""

    @functools.wraps(own)
    def __post_init__(self: Any) -> None:
        _check_field_types(self)
        own(self)

    __post_init__._types_checked = True  # type: ignore[attr-defined]
    return __post_init__


def _scalar_F_sx(raw: Callable[..., Any]) -> Callable[..., Any]:
    """``raw`` (a metric class's ``F_sx``) with its result checked: a scalar CasADi SX
    expression (a number is taken as a constant). A vector, None, a string, or an error
    raised while building the expression (numpy functions on CasADi symbols, for one) is an
    `InputError` naming the metric."""

    @functools.wraps(raw)
    def F_sx(self: Any, x: Any, v: Any) -> ca.SX:
        try:
            out = raw(self, x, v)
        except InputError:
            raise
        except Exception as err:  # a user's F: any error, reported in one line
            text = str(err).strip().splitlines()
            raise InputError(
                f"metric {_metric_name(self)!r}: F_sx(x, v) failed on CasADi symbols "
                f"({type(err).__name__}: {short(text[0] if text else '', 120)}); write F "
                "with CasADi operations (ca.sqrt, ca.dot, ca.fmax), not numpy or math"
            ) from err
        if out is None or isinstance(out, (str, bytes, bool, dict, list, tuple)):
            raise InputError(f"metric {_metric_name(self)!r}: F_sx(x, v) must return a scalar "
                             f"CasADi expression of x and v, got {type(out).__name__}")
        if not isinstance(out, (ca.SX, ca.MX)):
            try:
                out = ca.SX(out)
            except Exception as err:
                raise InputError(f"metric {_metric_name(self)!r}: F_sx(x, v) must return a "
                                 f"scalar CasADi SX expression of x and v, got "
                                 f"{type(out).__name__}") from err
        if out.shape != (1, 1):
            raise InputError(f"metric {_metric_name(self)!r}: F_sx(x, v) must return a "
                             f"scalar expression of x and v, got shape {out.shape}")
        return out

    F_sx._scalar_checked = True  # type: ignore[attr-defined]
    return F_sx


def _raise_non_finite(x: Any, v: Any) -> None:
    """Raise `InputError` if ``x`` or ``v`` holds NaN or inf (called only after a
    non-finite result, so the check costs nothing on good input)."""
    for arr in (x, v):
        finite = arr.isfinite() if is_torch(arr) else np.isfinite(arr)
        if not bool(finite.all()):
            raise InputError("input points or vectors contain NaN or inf")


def _ndim(a: Any) -> int:
    """``a``'s number of dimensions; -1 for what is no array (ragged lists: `as_real`
    then names the argument)."""
    if hasattr(a, "ndim"):
        return int(a.ndim)
    try:
        return int(np.ndim(a))
    except (ValueError, TypeError):
        return -1


def _same_kind(a: Any, b: Any) -> None:
    if is_torch(a) != is_torch(b):
        raise InputError("mix of numpy arrays and torch tensors: pass both as the same kind")


def _check_param(name: str, param: str, kind: str, value: Any) -> Any:
    """``value`` checked against the field annotation ``kind`` of the metric's class."""
    ok_types = _PARAM_KINDS.get(kind.replace(" ", ""))
    if ok_types is not None:
        ok = isinstance(value, ok_types) and (
            kind == "bool" or not isinstance(value, (bool, np.bool_)))
        if ok and kind == "float":
            ok = math.isfinite(value)
            value = float(value)
        elif ok:
            value = {"int": int, "bool": bool, "str": str}[kind](value)
        if not ok:
            raise InputError(f"metric parameter {param} of {short(name, 80)!r} must be {kind}"
                             f"{' (finite)' if kind == 'float' else ''}, got "
                             f"{type(value).__name__} {short(repr(value), 80)}")
        return value
    try:  # another annotation: anything JSON can hold, checked by the metric itself
        json.dumps(value, allow_nan=False)
    except (TypeError, ValueError, RecursionError) as err:
        raise InputError(f"metric parameter {param} of {short(name, 80)!r} must be a JSON "
                         f"value, got {type(value).__name__} {short(repr(value), 80)}"
                         ) from err
    return value


def check_params(name: str, cls: type, params: Mapping[str, Any]) -> dict[str, Any]:
    """``params`` checked against the field annotations of the metric class ``cls``
    (registered as ``name``): a ``float`` field takes a finite real number (not a bool),
    an ``int`` field an integer, a ``bool`` field a bool; other annotations any JSON
    value. The parameter names are the caller's to check."""
    fields = param_fields(cls)
    return {k: _check_param(name, k, fields[k], v) if k in fields else v
            for k, v in params.items()}


def param_fields(cls: type) -> dict[str, str]:
    """The parameters of a metric class (its init fields) and their annotations."""
    return {f.name: f.type.__name__ if isinstance(f.type, type) else str(f.type)
            for f in dataclasses.fields(cls) if f.init}
