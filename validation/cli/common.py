"""Helpers shared by the ``geodesics`` commands: clear one-line errors (exit code 2),
point parsing and metric look-up. The command modules import this, never ``cli``."""

from __future__ import annotations

import json
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

import finsler
from finsler.errors import InputError, short
from finsler.infra.modules import import_user_module

if TYPE_CHECKING:  # numpy is imported where used: --help stays light
    import numpy as np

__all__ = [
    "METHOD_MODULE_HELP",
    "METRIC_MODULE_HELP",
    "METRIC_PARAM_HELP",
    "SWEEP_METRIC_PARAM_HELP",
    "TRAINED_METRIC_PARAM_HELP",
    "MethodModuleOption",
    "MetricModuleOption",
    "MetricParamOption",
    "SweepMetricParamOption",
    "TrainedMetricParamOption",
    "fail",
    "import_metric_modules",
    "interrupted",
    "json_text",
    "metric_from_options",
    "metric_or_fail",
    "metric_param_option",
    "one_line",
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
#: Help of the ``--method-module`` option (every command that trains or reads a run).
METHOD_MODULE_HELP = ("Module (dotted name) or FILE.py to import first, so that the "
                      "learning methods it registers (learn.registry.register_method) can "
                      "be used (repeatable; a file's folder is put on sys.path, so sweep "
                      "workers import it too).")
#: Help of ``--metric-param`` where a run's policy is read (evaluate, report).
TRAINED_METRIC_PARAM_HELP = ("Metric parameter the policy must have been trained with "
                             "(repeatable; the run's own parameters are always used).")
#: Help of ``--metric-param`` for a sweep.
SWEEP_METRIC_PARAM_HELP = METRIC_PARAM_HELP + " Applies to every environment of the sweep."


def metric_param_option(help: str = METRIC_PARAM_HELP) -> Any:
    """The ``--metric-param NAME=VALUE`` option (repeatable) as a parameter type; the one
    definition of its flag and metavar, ``help`` fitting the command."""
    return Annotated[list[str] | None, typer.Option(
        "--metric-param", metavar="NAME=VALUE", help=help)]


#: The shared options as parameter types of a command: every command declares
#: ``metric_param: MetricParamOption = None`` (or the evaluate/report/sweep variant) and
#: ``metric_module: MetricModuleOption = None``, ``method_module: MethodModuleOption = None``.
MetricParamOption = metric_param_option()
TrainedMetricParamOption = metric_param_option(TRAINED_METRIC_PARAM_HELP)
SweepMetricParamOption = metric_param_option(SWEEP_METRIC_PARAM_HELP)
MetricModuleOption = Annotated[list[str] | None, typer.Option(
    "--metric-module", metavar="MODULE", help=METRIC_MODULE_HELP)]
MethodModuleOption = Annotated[list[str] | None, typer.Option(
    "--method-module", metavar="MODULE", help=METHOD_MODULE_HELP)]


#: Longest error line the commands print (characters, after ``error: ``).
MESSAGE_LIMIT = 200


def one_line(message: str, limit: int = MESSAGE_LIMIT) -> str:
    """``message`` on one line of at most ``limit`` characters (whitespace runs joined; a
    longer message keeps its start and end, the middle elided)."""
    text = " ".join(str(message).split())
    if len(text) <= limit:
        return text
    return text[: limit - 40] + " ... " + text[-35:]


def fail(message: str, code: int = 2) -> None:
    """Print a clear one-line error and exit with ``code`` (2: bad input, 1: the work
    failed)."""
    typer.echo(f"error: {one_line(message)}", err=True)
    raise typer.Exit(code=code)


#: How the running command was interrupted: ``signal`` (set by the CLI's SIGTERM handler;
#: otherwise SIGINT) and ``said`` (the command printed its own line, `interrupted`).
INTERRUPT: dict[str, Any] = {"signal": None, "said": False}


def interrupted(message: str) -> None:
    """Print the one line that says how the command stopped on SIGINT / SIGTERM and what
    was kept, and exit 130 (the entry point then prints nothing more)."""
    typer.echo(" ".join(str(message).split()), err=True)
    INTERRUPT["said"] = True
    raise typer.Exit(code=130)


def json_text(doc: Any, indent: int | None = 2) -> str:
    """Standard JSON of a command's result: numpy values as Python ones, and NaN or
    infinite numbers (which JSON cannot hold) as ``null``."""
    from validation.jsonout import jsonable

    return json.dumps(jsonable(doc), indent=indent, allow_nan=False)


def parse_point(text: str, dim: int, what: str) -> np.ndarray:
    """Parse ``"a,b,..."`` into a float64 vector of length ``dim``."""
    import numpy as np

    try:
        values = [float(t) for t in text.replace(" ", "").split(",") if t != ""]
    except ValueError:
        fail(f"{what} {short(text)!r} is not a comma-separated list of numbers")
    if len(values) != dim:
        fail(f"{what} needs {dim} comma-separated coordinates, got {len(values)} in "
             f"{short(text)!r}")
    arr = np.asarray(values, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        fail(f"{what} {short(text)!r} contains NaN or inf")
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
    except Exception as err:  # a user's metric class (--metric-module) may raise anything
        fail(f"--metric {short(name)}: building the metric raised {type(err).__name__}: "
             f"{short(str(err), 80)}")
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
            raise InputError(f"--metric-param expects NAME=VALUE, got {short(item)!r}")
        if key in out:
            raise InputError(f"--metric-param {short(key)} is given twice")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw.strip()
        out[key] = value
    return out


def import_metric_modules(items: list[str] | None) -> None:
    """Import every ``--metric-module`` (`finsler.infra.modules.import_user_module`: a
    dotted module name or a ``.py`` file; any failure is a one-line InputError)."""
    for item in items or []:
        import_user_module(item, "--metric-module")


def parse_overrides(items: list[str]) -> dict[str, Any]:
    """``["field=value", ...]`` -> ``{field: value}`` (values parsed as JSON, else kept as
    strings; lists become tuples). Which fields exist is
    checked by the command (``--set`` of ``train`` and ``sweep``)."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InputError(f"--set expects FIELD=VALUE, got {short(item)!r}")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        out[key] = tuple(value) if isinstance(value, list) else value
    return out


def output_path(value: str | Path) -> Path:
    """typer parser of an output path option (``--out``): the text the user typed as a
    path, refused when empty (``Path("")`` is the current folder, so ``--out ""`` would
    write there unasked)."""
    if isinstance(value, Path):
        return value
    if value.strip() == "":
        raise typer.BadParameter("an empty path names no file or folder")
    return Path(value)
