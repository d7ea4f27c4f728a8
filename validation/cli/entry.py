"""The ``geodesics`` command line: a thin layer over the Python API (typer).

Every command calls public functions of ``finsler``, ``solvers``, ``learn`` or
``validation``; nothing here is only reachable from the CLI.
"""

from __future__ import annotations

import importlib
import os
import signal
import sys
import threading
from typing import Annotated, Any

import typer

from finsler.errors import InputError
from finsler.infra.pool import PoolInterrupted
from validation.cli.common import (
    INTERRUPT,
    MetricModuleOption,
    MetricParamOption,
    fail,
    json_text,
    metric_from_options,
    one_line,
    parse_point,
)
from validation.text import text_table

app = typer.Typer(
    name="geodesics",
    help="Exact and learned geodesics on Finsler manifolds.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    # click's plain help instead of rich's panels: importing and rendering rich costs 0.1 s
    # of CPU, a third of the 0.3 s `geodesics CMD --help` may take
    rich_markup_mode=None,
)


@app.command("metrics")
def metrics_command(
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
) -> None:
    """List the registered metrics with their domains and task defaults."""
    # Listing does no linear algebra: one OpenBLAS thread spares the 0.08 s of CPU its
    # thread pool costs at numpy's import (geodesics metrics answers in < 0.3 s).
    # Without effect if numpy is imported already (the app called in-process).
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
    import finsler

    rows = []
    for n in finsler.list_metrics():
        try:
            rows.append(finsler.get_metric(n).info())
        except Exception as err:  # a user's metric (registered by a module) may be broken
            fail(f"metric {n!r} cannot be described: {type(err).__name__}: {err}")
    if as_json:
        typer.echo(json_text(rows))
        return
    head = ("name", "dim", "domain", "D", "eps", "reversible", "hooks", "convexity")
    table = [head] + [
        (
            r["name"],
            str(r["dim"]),
            r["domain"],
            str(r["depth"]),
            f"{r['eps']:g}",
            "yes" if r["reversible"] else "no",
            ",".join(r["hooks"]) or "-",
            r["convexity"],
        )
        for r in rows
    ]
    typer.echo(text_table(table))


@app.command("cost", short_help="Local costs between two points: C, symmetric C, segment "
             "length with an error estimate.")
def cost_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    start: Annotated[str, typer.Option(help='Start point, e.g. "0.1,-0.2".')],
    goal: Annotated[str, typer.Option(help='Goal point, e.g. "0.5,0.3".')],
    order: Annotated[int | None, typer.Option(
        help="Also give the fixed-order Gauss-Legendre length of this order, with its "
             "difference to the accurate length (a warning if it is off).")] = None,
    rtol: Annotated[float, typer.Option(
        help="Relative tolerance of the segment length (adaptive Gauss-Kronrod).")] = 1e-10,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
) -> None:
    """Local costs between two points: C (eq. 4), symmetric C (eq. 59), segment length (eq. 58)
    with an error estimate (adaptive quadrature to --rtol; a warning if not reached)."""
    m = metric_from_options(metric, metric_param, metric_module)
    s = parse_point(start, m.dim, "--start")
    g = parse_point(goal, m.dim, "--goal")
    warnings = []
    try:
        m.domain.check(s, "--start")
        m.domain.check(g, "--goal")
        if order is not None and order < 1:
            raise InputError(f"--order must be >= 1, got {order}")
        if not (rtol > 0 and rtol < 1):
            raise InputError(f"--rtol must be in (0, 1), got {rtol!r}")
        est = m.segment_length_error(s, g, rtol=rtol)
        out = {
            "metric": m.name,
            "cost": float(m.cost(s, g)),
            "cost_symmetric": float(m.cost_symmetric(s, g)),
            "segment_length": est.value,
            "segment_length_error": est.error,
            "segment_length_converged": est.converged,
            "quadrature_intervals": est.intervals,
        }
        if not est.converged:
            warnings.append(f"the segment length reached an error of {est.error:.3g} "
                            f"(relative {est.error / max(est.value, 1e-300):.3g}), above "
                            f"--rtol {rtol:g}: the segment is too long or F too rough")
        if order is not None:
            fixed = float(m.segment_length(s, g, order=order))
            diff = fixed - est.value
            out["segment_length_order"] = {"order": order, "value": fixed, "difference": diff}
            if abs(diff) > max(10 * est.error, 1e-9 * abs(est.value)):
                warnings.append(f"Gauss-Legendre order {order} gives {fixed:.12g}, off by "
                                f"{diff:+.3g} ({diff / est.value:+.2%}) from the accurate "
                                f"length {est.value:.12g}: use a higher --order")
    except InputError as err:
        fail(str(err))
    out["warnings"] = warnings
    for w in warnings:
        typer.echo(f"warning: {w}", err=True)
    if as_json:
        typer.echo(json_text(out))
    else:
        typer.echo(f"C(start, goal)           = {out['cost']:.12g}")
        typer.echo(f"symmetric C (eq. 59)     = {out['cost_symmetric']:.12g}")
        typer.echo(f"segment length (eq. 58)  = {out['segment_length']:.12g} "
                   f"+- {out['segment_length_error']:.2g}")
        if order is not None:
            fo = out["segment_length_order"]
            typer.echo(f"Gauss-Legendre order {order:<4d} = {fo['value']:.12g} "
                       f"(difference {fo['difference']:+.3g})")


def _register_optional_commands() -> None:
    """Commands of the other layers, registered here so the CLI stays one entry point."""
    for name in ("solve", "train", "report", "plot", "sweep", "expmap", "certify", "check",
                 "field"):
        importlib.import_module(f"validation.cli.{name}").register(app)


_register_optional_commands()


def _click_error(name: str) -> type[Exception]:
    """click's exception class ``name`` as the installed typer uses it (recent typers
    vendor click, older ones use the click package: the class is found from typer's own
    ``BadParameter``, which derives from both)."""
    return next(c for c in typer.BadParameter.__mro__ if c.__name__ == name)


class _Terminated(KeyboardInterrupt):
    """SIGTERM in the main thread, raised like Ctrl-C's KeyboardInterrupt: every command
    then stops the same way (exit 130, one line, files written atomically or not at all).
    Training loops and process pools install their own handlers while they run."""


def _on_sigterm(signum: int, frame: Any) -> None:
    INTERRUPT["signal"] = "SIGTERM"
    raise _Terminated


def main(args: list[str] | None = None) -> None:
    """Console-script entry point. A usage error (unknown option or command, missing or
    malformed value) is one line, ``error: ... (see 'geodesics CMD --help')``, exit 2, like
    every other bad input, instead of click's boxed usage panel; no command at all prints
    the help (exit 2)."""
    argv = sys.argv[1:] if args is None else list(args)
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)
    try:
        code = app(args=argv, standalone_mode=False)
    except _click_error("UsageError") as err:
        if type(err).__name__ == "NoArgsIsHelpError":  # the help is its message (plain
            text = err.format_message()  # help; rich's help printed itself, returning "")
            if text:
                typer.echo(text)
            sys.exit(2)
        ctx = getattr(err, "ctx", None)
        where = ctx.command_path if ctx is not None else "geodesics"
        typer.echo(f"error: {one_line(err.format_message())} (see '{where} --help')",
                   err=True)
        sys.exit(2)
    except _click_error("ClickException") as err:  # pragma: no cover - other click errors
        typer.echo(f"error: {one_line(err.format_message())}", err=True)
        sys.exit(getattr(err, "exit_code", 1))
    except PoolInterrupted as stop:  # a command that did not say more itself
        typer.echo(f"interrupted ({stop.signal_name})", err=True)
        sys.exit(130)
    except (KeyboardInterrupt, typer.Abort) as stop:  # pragma: no cover - interactive
        typer.echo(f"interrupted ({'SIGTERM' if isinstance(stop, _Terminated) else 'SIGINT'})",
                   err=True)
        sys.exit(130)
    if code == 130 and not INTERRUPT["said"]:  # typer turns KeyboardInterrupt into exit 130
        typer.echo(f"interrupted ({INTERRUPT['signal'] or 'SIGINT'})", err=True)
    sys.exit(code if isinstance(code, int) else 0)


if __name__ == "__main__":  # pragma: no cover
    main()
