"""``geodesics report``: the learned-vs-exact benchmark report (a thin layer over
[`validation.report.build_report`][validation.report.build_report])."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated

import typer

from finsler.errors import InputError
from finsler.infra.files import check_input_dir, check_output_dir
from validation.cli.common import (
    MethodModuleOption,
    MetricModuleOption,
    TrainedMetricParamOption,
    fail,
    import_metric_modules,
    interrupted,
    output_path,
    parse_metric_params,
)

__all__ = ["register", "report_command"]


def report_command(
    out: Annotated[Path, typer.Option(
        parser=output_path,
        help="Output folder for report.md, report.json and the PNG figures (created if "
             "missing).")],
    env: Annotated[str | None, typer.Option(
        help="Environment (see `geodesics metrics`); uses its shipped policy unless --run "
             "is given (an environment without one needs --run, or --quick to train "
             "one).")] = None,
    run: Annotated[Path | None, typer.Option(help="Run directory written by `geodesics "
                                             "train`.")] = None,
    pairs: Annotated[Path | None, typer.Option(
        help="PAIRS.npy of shape (K, 2, dim); default: the environment's 100 default "
             "evaluation pairs.")] = None,
    quick: Annotated[bool, typer.Option(
        "--quick", help="Skip continuum distances and certify fewer pairs on a coarser "
        "mesh. Without --run, on an environment without a shipped policy (any metric, a "
        "user's too): first train its default configuration for 3e6 evaluations of C into "
        "OUT/quick_run (said first, with a progress bar; interrupted, the same command "
        "resumes it); a shipped policy is used as it is.")] = False,
    continuum: Annotated[bool | None, typer.Option(
        "--continuum/--no-continuum",
        help="Continuum distances for the midpoint error where the metric is Finsler along "
             "the path (default: on unless --quick).")] = None,
    checkpoint: Annotated[str, typer.Option(
        help="best (selected on the validation set during training) or latest.")] = "best",
    workers: Annotated[int | None, typer.Option(
        help="Processes for the exact solves (default: CPU count).")] = None,
    progress: Annotated[bool, typer.Option("--progress/--no-progress",
                                           help="Show progress bars.")] = True,
    metric_param: TrainedMetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method_module: MethodModuleOption = None,
    search: Annotated[bool, typer.Option(
        "--search/--no-search",
        help="Also report the policy with the route search (learn.midpoint.search: candidate "
             "midpoints at the top levels chosen by the cost of the policy's completed "
             "paths; values of C only).")] = True,
    certify: Annotated[int | None, typer.Option(
        help="Certified intervals lower <= d <= upper (solvers.certify, any dimension it "
             "accepts; beyond 2-D the lower bound may be far from the upper one) for this "
             "many pairs, with proven bounds on the learned paths' excess length (default "
             "in 2-D: 2 with --quick on the coarse mesh, else 5 on the default mesh; beyond "
             "2-D: 1 with --quick, else 2, on the coarse preset; 0: none).")] = None,
) -> None:
    """Benchmark a learned policy against exact geodesics and the straight-line baseline:
    success rates, length ratios, midpoint errors, timing, figures."""
    import learn
    from finsler.infra.pool import PoolInterrupted
    from validation.report import build_report, quick_training_note
    from validation.report_certify import cli_lines

    try:
        if workers is not None and workers < 1:
            raise InputError(f"--workers must be >= 1, got {workers}")
        check_output_dir(out, "--out")
        if run is not None:
            check_input_dir(run, "--run")
        import_metric_modules(metric_module)
        learn.import_method_modules(method_module)
        params = parse_metric_params(metric_param)
        note = quick_training_note(env, run, quick, out)
        if note is not None:
            typer.echo(note)
        doc = build_report(env, out, run=run, pairs=pairs, quick=quick, continuum=continuum,
                           workers=workers, progress=progress, checkpoint=checkpoint,
                           metric_params=params, search=search, certify=certify)
    except InputError as err:
        fail(str(err))
        return
    except learn.TrainingInterrupted as stop:
        interrupted(f"interrupted ({stop.signal_name}) while training the --quick policy: "
                    f"it is kept in {stop.run_dir} at {stop.timesteps} evaluations of C, and "
                    "the same command resumes it; no report written")
    except PoolInterrupted as stop:
        interrupted(f"interrupted ({stop.signal_name}) during the exact solves, all workers "
                    "stopped; no report written")
    sr = doc["success_rate"]
    lr = doc["length_ratio"]["learned"]["length"]
    mp = ", ".join(f"{k}={v}" for k, v in (doc.get("metric_params") or {}).items())
    typer.echo(f"report for {doc['metric']}{f' ({mp})' if mp else ''} ({doc['pairs']} pairs) "
               f"written to {out}/report.md")
    typer.echo(f"policy: {doc['policy_note']}")
    typer.echo(f"success: learned {sr['learned']:.0%}, exact ceiling {sr['exact_ceiling']:.0%}, "
               f"straight line {sr['straight']:.0%}")
    if lr["mean"] is not None:
        typer.echo(f"length learned/exact: mean {lr['mean']:.4f}, median {lr['median']:.4f}, "
                   f"95th pct {lr['p95']:.4f}, max {lr['max']:.4f}")
    if "searched" in sr:
        sl = doc["length_ratio"]["searched"]["length"]
        typer.echo(f"with route search ({doc['search']['evaluations_of_C_per_path']:.0f} "
                   f"evaluations of C per path): success {sr['searched']:.0%}, length/exact "
                   f"mean {sl['mean']:.4f}, median {sl['median']:.4f}, 95th pct "
                   f"{sl['p95']:.4f}, max {sl['max']:.4f}")
    t = doc["timing"]
    typer.echo(f"time per path ({t.get('threads', '?')} torch thread): learned "
               f"{t['learned_seconds_per_path_batched']:.3g} s at batch "
               f"{t.get('learned_batch', doc['pairs']):,}, exact {t['exact_seconds_per_path']:.3g}"
               f" s (batch of {doc['pairs']}): {t['speedup_batched']:.3g}x faster")
    for line in cli_lines(doc):
        typer.echo(line)
    typer.echo(f"figures: {', '.join(doc['figures'])}")


def register(app: typer.Typer) -> None:
    """Add ``report`` to the ``geodesics`` app."""
    app.command("report")(report_command)
