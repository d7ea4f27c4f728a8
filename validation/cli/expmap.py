"""``geodesics exp`` and ``geodesics log``: the exponential and logarithm maps of a metric
(thin layer over [`solvers.exp_map`][solvers.exp_map] / [`solvers.log_map`][solvers.log_map]).

JSON schemas: ``exp`` prints `solvers.ExpResult.to_dict` (``point``, ``t_end``,
``status``, ``speed``, ``length`` = speed x t_end, ``speed_drift``, and ``times``/``curve``
with ``--samples``); ``log`` prints `solvers.LogResult.to_dict` (``velocity``,
``length`` = F(start, velocity), ``distance`` of the solved path, ``residual``, ``status``).
Exit code 2 for bad input (including a metric that is not smooth or not strongly convex
where asked), 1 when the status is not a success.
"""

from __future__ import annotations

from typing import Annotated

import typer

import solvers
from finsler.errors import InputError
from finsler.infra.limits import check_memory
from validation.cli.common import (
    MetricModuleOption,
    MetricParamOption,
    fail,
    json_text,
    metric_from_options,
    one_line,
    parse_point,
)

__all__ = ["exp_command", "log_command", "register"]


def exp_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    start: Annotated[str, typer.Option(help='Start point x, e.g. "0.1,-0.2".')],
    velocity: Annotated[str, typer.Option(help='Initial velocity v, e.g. "0.5,0.3".')],
    t: Annotated[float, typer.Option("--t", help="Time to integrate to (>= 0).")] = 1.0,
    samples: Annotated[int, typer.Option(
        help="Also return this many points of the curve on [0, t_end] (0: none).")] = 0,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
) -> None:
    """exp(x, v): the end point at time t of the geodesic from x with initial velocity v."""
    import numpy as np

    m = metric_from_options(metric, metric_param, metric_module)
    x = parse_point(start, m.dim, "--start")
    v = parse_point(velocity, m.dim, "--velocity")
    if samples < 0 or samples == 1:
        fail(f"--samples must be 0 or >= 2, got {samples}")
    try:  # before anything is allocated
        check_memory((samples, 2 * m.dim), f"--samples {samples}", copies=3)
    except InputError as err:
        fail(str(err))
    try:
        if not (np.isfinite(t) and t >= 0):
            raise InputError(f"--t must be a finite number >= 0, got {t!r}")
        r = solvers.exp_map(m, x, v, t=t, return_curve=samples if samples else False,
                            names=("--start", "--velocity"))
    except InputError as err:
        fail(str(err))
        raise  # unreachable
    if as_json:
        typer.echo(json_text(r.to_dict()))
    else:
        typer.echo(f"status        {r.status.label}" + (f" ({r.message})" if r.message else ""))
        typer.echo(f"point         {np.array2string(r.point, precision=12)}")
        typer.echo(f"t_end         {r.t_end:.12g}")
        typer.echo(f"speed F(x,v)  {r.speed:.12g}")
        typer.echo(f"length        {r.speed * r.t_end:.12g}")
        typer.echo(f"speed drift   {r.speed_drift:.2e}")
        typer.echo(f"wall time     {r.wall_time:.3f} s")
    if not r.converged:  # the result above says why; stderr says that it is not the answer
        stopped(f"the geodesic stopped at t = {r.t_end:.6g} before t = {t:.6g}: "
                f"{r.status.label}")


def log_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    start: Annotated[str, typer.Option(help='Start point x, e.g. "0.1,-0.2".')],
    goal: Annotated[str, typer.Option(help='Goal point y, e.g. "0.5,0.3".')],
    tol: Annotated[float, typer.Option(help="Tolerance on |exp(x, v) - y| (max norm).")] = 1e-11,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
) -> None:
    """log(x, y): the initial velocity v of the shortest geodesic with exp(x, v) = y."""
    import numpy as np

    m = metric_from_options(metric, metric_param, metric_module)
    x = parse_point(start, m.dim, "--start")
    y = parse_point(goal, m.dim, "--goal")
    try:
        if not (np.isfinite(tol) and 0 < tol < 1):
            raise InputError(f"--tol must be in (0, 1), got {tol!r}")
        r = solvers.log_map(m, x, y, tol=float(tol), names=("--start", "--goal"))
    except InputError as err:
        fail(str(err))
        raise  # unreachable
    if as_json:
        typer.echo(json_text(r.to_dict()))
    else:
        typer.echo(f"status         {r.status.label}")
        typer.echo(f"velocity       {np.array2string(r.velocity, precision=12)}")
        typer.echo(f"F(x, v)        {r.length:.12g}")
        typer.echo(f"distance       {r.distance:.12g}  (solver, estimate "
                   f"{r.distance_error_estimate:.1e})")
        typer.echo(f"residual       {r.residual:.2e}")
        typer.echo(f"Newton steps   {r.iterations}")
        typer.echo(f"wall time      {r.wall_time:.3f} s")
    if not r.converged:
        stopped(f"log did not converge: {r.status.label} (residual {r.residual:.2e})")


def stopped(message: str) -> None:
    """A result that is not the answer asked for: one line on stderr, exit code 1 (the
    result itself, with its status, is on stdout)."""
    typer.echo(f"note: {one_line(message)}", err=True)
    raise typer.Exit(code=1)


def register(app: typer.Typer) -> None:
    """Add ``exp`` and ``log`` to the ``geodesics`` app."""
    app.command("exp")(exp_command)
    app.command("log")(log_command)
