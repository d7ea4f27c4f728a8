"""The ``geodesics`` command line: a thin layer over the Python API (typer).

Every command calls public functions of ``finsler``, ``solvers``, ``learn`` or
``validation``; nothing here is only reachable from the CLI.
"""

from __future__ import annotations

import json
import sys
from typing import Annotated

import typer

import finsler
from finsler.errors import InputError
from validation.cli_common import fail, metric_or_fail, parse_point

app = typer.Typer(
    name="geodesics",
    help="Exact and learned geodesics on Finsler manifolds.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
)


@app.command("metrics")
def metrics_command(
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")] = False,
) -> None:
    """List the registered metrics with their domains and task defaults."""
    rows = [finsler.get_metric(n).info() for n in finsler.list_metrics()]
    if as_json:
        typer.echo(json.dumps(rows, indent=2))
        return
    head = ("name", "dim", "domain", "D", "eps", "reversible", "convexity")
    table = [head] + [
        (
            r["name"],
            str(r["dim"]),
            r["domain"],
            str(r["depth"]),
            f"{r['eps']:g}",
            "yes" if r["reversible"] else "no",
            r["convexity"],
        )
        for r in rows
    ]
    widths = [max(len(row[i]) for row in table) for i in range(len(head))]
    for k, row in enumerate(table):
        typer.echo("  ".join(c.ljust(w) for c, w in zip(row, widths)).rstrip())
        if k == 0:
            typer.echo("  ".join("-" * w for w in widths))


@app.command("cost")
def cost_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    start: Annotated[str, typer.Option(help='Start point, e.g. "0.1,-0.2".')],
    goal: Annotated[str, typer.Option(help='Goal point, e.g. "0.5,0.3".')],
    order: Annotated[int, typer.Option(help="Gauss-Legendre order for the segment length.")] = 8,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Local costs between two points: C (eq. 4), symmetric C (eq. 59), segment length (eq. 58)."""
    m = metric_or_fail(metric)
    s = parse_point(start, m.dim, "--start")
    g = parse_point(goal, m.dim, "--goal")
    try:
        m.domain.check(s, "--start")
        m.domain.check(g, "--goal")
        if order < 1:
            raise InputError(f"--order must be >= 1, got {order}")
        out = {
            "metric": m.name,
            "cost": float(m.cost(s, g)),
            "cost_symmetric": float(m.cost_symmetric(s, g)),
            "segment_length": float(m.segment_length(s, g, order=order)),
        }
    except InputError as err:
        fail(str(err))
    if as_json:
        typer.echo(json.dumps(out, indent=2))
    else:
        typer.echo(f"C(start, goal)           = {out['cost']:.12g}")
        typer.echo(f"symmetric C (eq. 59)     = {out['cost_symmetric']:.12g}")
        typer.echo(f"segment length (eq. 58)  = {out['segment_length']:.12g}")


def _register_optional_commands() -> None:
    """Commands of the other layers, registered here so the CLI stays one entry point."""
    from validation import cli_learn, cli_plot, cli_report, cli_solve, cli_sweep

    for module in (cli_solve, cli_learn, cli_report, cli_plot, cli_sweep):
        module.register(app)


_register_optional_commands()


def main() -> None:
    """Console-script entry point."""
    try:
        app()
    except KeyboardInterrupt:  # pragma: no cover - interactive
        typer.echo("interrupted", err=True)
        sys.exit(130)


if __name__ == "__main__":  # pragma: no cover
    main()
