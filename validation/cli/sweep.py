"""``geodesics sweep``: every (environment, variant, seed) as its own run directory, on a
local process pool or on a Ray cluster; a thin CLI over `learn.sweep`."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from finsler.errors import InputError
from finsler.infra.files import check_output_dir
from finsler.infra.pool import PoolInterrupted
from validation.cli.common import (
    MethodModuleOption,
    MetricModuleOption,
    SweepMetricParamOption,
    fail,
    import_metric_modules,
    interrupted,
    json_text,
    output_path,
    parse_metric_params,
    parse_overrides,
)
from validation.text import text_table

__all__ = ["format_table", "register", "sweep_command"]


def _split(text: str) -> list[str]:
    return [t.strip() for t in text.split(",") if t.strip()]


def _cell(v: Any, key: str) -> str:
    if v is None:
        return "-"
    if key == "success_rate":
        return f"{v:.2%}"
    if key == "wall_seconds":
        return f"{v:.1f}"
    return str(v)


def format_table(rows: list[dict[str, Any]]) -> str:
    """The sweep's final table: env, variant, seed, action, stopped_by, timesteps, wall
    seconds (training, cumulative), final validation success."""
    keys = ("env", "variant", "seed", "action", "stopped_by", "timesteps", "wall_seconds",
            "success_rate")
    head = ("env", "variant", "seed", "action", "stopped by", "timesteps", "wall s",
            "val. success")
    table = [head] + [tuple(_cell(r[k], k) for k in keys) for r in rows]
    return text_table(table)


def metric_overrides(envs: list[str], params: dict[str, Any] | None) -> dict[str, Any]:
    """Config overrides for the sweep's metric: ``metric_params`` (the same for every
    environment), and ``metric_class`` for a metric registered outside the toolkit, so
    that worker processes (spawned, or on Ray) import it. A user metric is swept alone."""
    import finsler
    from finsler.spec import class_path

    out: dict[str, Any] = {}
    if params is not None:
        out["metric_params"] = params
    user = {}
    for e in envs:
        if e in finsler.list_metrics():
            path = class_path(finsler.metric_class(e))
            if path is not None:
                user[e] = path
    if user:
        if len(envs) > 1:
            raise InputError(f"sweep the user metric(s) {', '.join(user)} alone (one --envs "
                             "entry): the workers import its class from the run's config")
        out["metric_class"] = next(iter(user.values()))
    return out


def sweep_command(
    envs: Annotated[str, typer.Option(help="Comma-separated environments, e.g. "
                                           "matsumoto,carlike.")],
    methods: Annotated[str, typer.Option(
        help="Comma-separated variants: midpoint, midpoint-free, paper, inter, two-to-one, "
             "seq, pg, or those of a method of --method-module.")],
    seeds: Annotated[int, typer.Option(help="Number of seeds N: runs use seeds 0..N-1.")],
    out: Annotated[Path, typer.Option(
        parser=output_path,
        help="Sweep folder: runs go to OUT/<env>/<variant>/seed-<s>/, the plan and the "
             "status of every run to OUT/sweep.json.")],
    timesteps: Annotated[int | None, typer.Option(
        help="Budget of every run: evaluations of C, all-inclusive (default: each "
             "variant's default for the environment).")] = None,
    minutes: Annotated[float | None, typer.Option(
        help="Wall-clock limit of every run in minutes (cumulative across resumes); a run "
             "stops at whichever limit comes first.")] = None,
    workers: Annotated[int | None, typer.Option(
        help="Local worker processes (default min(2, runs)); with --ray, the most tasks in "
             "flight (default: all, the cluster schedules them).")] = None,
    ray: Annotated[str | None, typer.Option(
        "--ray", metavar="ADDRESS",
        help="Run on Ray: HOST:6379 or auto (a running cluster), or local (start a local "
             "Ray instance). Needs Ray: the project's 'distributed' extra.")] = None,
    settings: Annotated[list[str] | None, typer.Option(
        "--set", metavar="FIELD=VALUE",
        help="Override a config field in every variant whose config has it (repeatable; "
             "VALUE is JSON or a bare string), e.g. --set eval_every=10.")] = None,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    as_json: Annotated[bool, typer.Option("--json", help="Print the rows as JSON.")] = False,
    metric_param: SweepMetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method_module: MethodModuleOption = None,
) -> None:
    """Train every (environment, variant, seed) into its own run directory: finished runs
    are skipped, unfinished ones resumed, absent ones started, so an interrupted sweep is
    completed by running the same command again.

    Locally the runs share a process pool (one torch thread each). With --ray each run is a
    Ray task: it is sent its run directory's files, trains in a temporary folder on the
    worker and sends the files back, so the cluster's machines need the project installed
    but no shared filesystem. Exit status 1 if a run failed (the others still finish)."""
    import learn

    try:
        if workers is not None and workers < 1:
            raise InputError(f"--workers must be a positive integer, got {workers}")
        check_output_dir(out, "--out")
        import_metric_modules(metric_module)
        learn.import_method_modules(method_module)
        overrides = parse_overrides(settings or [])
        for key, option in (("metric_params", "--metric-param"),
                            ("metric_class", "--metric-module")):
            if key in overrides:
                raise InputError(f"--set {key}=... is not allowed; use {option}")
        overrides.update(metric_overrides(_split(envs), parse_metric_params(metric_param)))
        plan = learn.plan_sweep(_split(envs), _split(methods), seeds, timesteps=timesteps,
                                minutes=minutes, overrides=overrides)
        result = learn.run_sweep(plan, out, workers=workers, ray_address=ray,
                                 progress=not quiet)
    except InputError as err:
        fail(str(err))
        return
    except PoolInterrupted as stop:
        interrupted(f"interrupted ({stop.signal_name}): every worker saved its run and "
                    f"stopped; finished runs are kept in {out} (status in "
                    f"{out / learn.SWEEP_FILE}); run the same command to resume")
    rows = result.rows()
    if as_json:
        typer.echo(json_text(rows))
    else:
        typer.echo(format_table(rows))
        typer.echo(f"{len(rows)} runs in {result.seconds:.1f} s ({result.backend}); "
                   f"plan and status in {out / learn.SWEEP_FILE}")
    if result.failed:
        typer.echo(f"{len(result.failed)} run(s) failed:", err=True)
        for o in result.failed:
            typer.echo(f"  {o.spec.rel_dir}: {o.error}", err=True)
        raise typer.Exit(code=1)


def register(app: typer.Typer) -> None:
    """Add ``sweep`` to the ``geodesics`` app."""
    app.command("sweep")(sweep_command)
