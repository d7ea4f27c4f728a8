"""Helpers shared by the ``geodesics`` commands: clear one-line errors (exit code 2),
point parsing and metric look-up. The command modules import this, never ``cli``."""

from __future__ import annotations

import json
from typing import Annotated, Any

import numpy as np
import typer

import finsler
from finsler.errors import InputError
from finsler.plugins import import_module_or_file

__all__ = [
    "METHOD_MODULE_HELP",
    "METRIC_MODULE_HELP",
    "METRIC_PARAM_HELP",
    "MetricModuleOption",
    "MetricParamOption",
    "fail",
    "import_metric_modules",
    "metric_from_options",
    "metric_or_fail",
    "parse_metric_params",
    "parse_overrides",
    "parse_point",
]

#: Help of the ``--metric-param`` option shared by the commands.
METRIC_PARAM_HELP = ("Metric parameter NAME=VALUE (repeatable; numbers parsed), e.g. "
                     "--metric-param a=0.2 for finsler.get_metric(env, a=0.2).")
#: Help of the ``--metric-module`` option shared by the commands.
METRIC_MODULE_HELP = ("Module (dotted name) or FILE.py to import first, so that the "
                      "metrics it registers (@finsler.register_metric) can be used "
                      "(repeatable; a file's folder is put on sys.path).")
#: Help of the ``--method-module`` option (``train``, ``evaluate``, ``sweep``).
METHOD_MODULE_HELP = ("Module (dotted name) or FILE.py to import first, so that the "
                      "learning methods it registers (learn.registry.register_method) can "
                      "be used (repeatable; a file's folder is put on sys.path, so sweep "
                      "workers import it too).")
#: The two options as parameter types of a command.
MetricParamOption = Annotated[list[str] | None, typer.Option(
    "--metric-param", metavar="NAME=VALUE", help=METRIC_PARAM_HELP)]
MetricModuleOption = Annotated[list[str] | None, typer.Option(
    "--metric-module", metavar="MODULE", help=METRIC_MODULE_HELP)]


def fail(message: str) -> None:
    """Print a clear error and exit with status 2 (bad input)."""
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code=2)


def parse_point(text: str, dim: int, what: str) -> np.ndarray:
    """Parse ``"a,b,..."`` into a float64 vector of length ``dim``."""
    try:
        values = [float(t) for t in text.replace(" ", "").split(",") if t != ""]
    except ValueError:
        fail(f"{what} {text!r} is not a comma-separated list of numbers")
    if len(values) != dim:
        fail(f"{what} needs {dim} comma-separated coordinates, got {len(values)} in {text!r}")
    arr = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        fail(f"{what} {text!r} contains NaN or inf")
    return arr


def metric_or_fail(name: str, params: dict[str, Any] | None = None) -> finsler.Metric:
    """The metric ``name`` with ``params`` (checked: unknown or ill-typed parameters name
    the allowed ones), or a clear error and exit status 2."""
    try:
        if params is None:
            return finsler.get_metric(name)
        return finsler.MetricSpec.resolve(name, params, what="metric").build()
    except InputError as err:
        fail(str(err))
        raise  # unreachable


def metric_from_options(name: str, metric_param: list[str] | None,
                        metric_module: list[str] | None) -> finsler.Metric:
    """The metric of a command's ``--metric``, ``--metric-param`` and ``--metric-module``
    options (modules imported first), or a clear error and exit status 2."""
    try:
        import_metric_modules(metric_module)
        params = parse_metric_params(metric_param)
    except InputError as err:
        fail(str(err))
    return metric_or_fail(name, params)


def parse_metric_params(items: list[str] | None) -> dict[str, Any] | None:
    """``["name=value", ...]`` (``--metric-param``) -> ``{name: value}``; values are
    parsed as JSON (numbers, true/false, lists), else kept as strings. None if no item.
    Which names exist is checked against the metric (``finsler.MetricSpec.resolve``)."""
    if not items:
        return None
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key or not raw.strip():
            raise InputError(f"--metric-param expects NAME=VALUE, got {item!r}")
        if key in out:
            raise InputError(f"--metric-param {key} is given twice")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw.strip()
        out[key] = value
    return out


def import_metric_modules(items: list[str] | None) -> None:
    """Import every ``--metric-module``: a dotted module name, or a ``.py`` file (its
    folder is put first on ``sys.path`` and it is imported by its stem, so that the
    recorded ``module:qualname`` of its metrics imports again, also in worker processes)."""
    for item in items or []:
        import_module_or_file(item, "--metric-module")


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["field=value", ...]`` -> ``{field: value}`` (values parsed as JSON, else kept as
    strings; lists become tuples). Which fields exist is
    checked by the command (``--set`` of ``train`` and ``sweep``)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InputError(f"--set expects FIELD=VALUE, got {item!r}")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        out[key] = tuple(value) if isinstance(value, list) else value
    return out
