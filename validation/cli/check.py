"""``geodesics check``: the property suite of `validation.testing` on a metric (and a
policy), as a table of property, examples tried, passed, result and counterexample.

Each property ends ``passed``; ``failed`` (a counterexample, with both sides' values);
``inconclusive`` (no counterexample, but some examples could not be judged: a solve that
did not converge -- never a counterexample --, a certificate out of its work budget; the
note says which and what was tried); ``mapped`` (failures only in a non-convex region the
metric documents); ``skipped`` (does not apply: e.g. distance symmetry on a metric
declared not reversible); or ``not-run`` (a property it needs failed: once F itself fails
-- domain, finite-positive, homogeneity, subadditivity, strong convexity, lowered forms,
smoothness -- the properties that need a valid F say "needs X" instead of failing as a
consequence; `validation.testing.suite.NEEDS`). The last line names the root cause
(the first failed property) first.

Exit status 0 when no property fails (inconclusive, mapped, skipped and not-run results
included; with ``--strict`` an inconclusive one exits 1 too), 1 when one fails, 2 for bad
input. The same ``--seed`` (with the same code loaded) gives the same examples and
results. Nothing is written: hypothesis's caches go to a temporary folder, removed at the
end. Warnings raised while checking (numpy's RuntimeWarnings on invalid values) are caught
and summarised per property, not printed as they come.

``--json`` prints `validation.testing.CheckReport.to_dict`: ``metric``, ``params``,
``policy``, ``seed``, ``examples``, ``ok`` (no property failed), ``failed``,
``inconclusive`` and ``not_run`` (names, in the order checked: the first failed is the
root cause), ``summary`` (the last line of the table), ``seconds`` and ``properties``, one
dict per property (``name``, ``claim``, ``status``: one of ``passed``, ``failed``,
``inconclusive``, ``mapped``, ``skipped``, ``not-run``; ``tried``, ``passed``, ``mapped``,
``inconclusive`` (examples not judged), ``counterexample``, ``lhs`` / ``rhs`` (``label``,
``value``), ``relation``, ``note``, ``needs`` (the properties it depends on),
``warnings`` (caught, with counts), ``shrink_evaluations``, ``shrink_limited``,
``seconds``). Non-finite values are written as text (``"nan"``), never as bare NaN.
"""

from __future__ import annotations

import json
import tempfile
from typing import TYPE_CHECKING, Annotated

import typer

from finsler.errors import InputError
from validation.cli.common import (
    MethodModuleOption,
    MetricModuleOption,
    MetricParamOption,
    fail,
    metric_from_options,
    one_line,
    parse_metric_params,
)

if TYPE_CHECKING:  # imported in check_command: hypothesis and the suite cost 0.2 s
    from validation.testing.engine import PropertyResult

__all__ = ["check_command", "register"]


def check_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    run: Annotated[str | None, typer.Option(
        help="Also check a policy: a run directory, or an environment with a shipped "
             "policy; it must be for --metric with the same parameters.")] = None,
    checkpoint: Annotated[str, typer.Option(help="Checkpoint of --run: best or latest.")
                          ] = "best",
    examples: Annotated[int, typer.Option(
        help="Hypothesis examples per property of F; properties that solve geodesics use "
             "examples/30 (at least 3), the policy's fresh pairs examples/10 (at least 4).")
                        ] = 100,
    seed: Annotated[int, typer.Option(help="Seed of every search (same seed, same result).")
                    ] = 0,
    min_success: Annotated[float, typer.Option(
        help="--run: smallest success rate on fresh pairs.")] = 0.8,
    max_length_ratio: Annotated[float, typer.Option(
        help="--run: largest mean length ratio learned/exact on fresh pairs.")] = 1.3,
    midpoint_tol: Annotated[float, typer.Option(
        help="--run: largest first-level midpoint error (relative to d) per pair, and "
             "largest L(pi(x,y), pi(y,x)) / L(x,y) (segment lengths) on reversible "
             "metrics.")] = 0.25,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON instead of a table.")
                       ] = False,
    strict: Annotated[bool, typer.Option(
        "--strict", help="Exit 1 when a property is inconclusive (a solve that did not "
                         "converge, a certificate out of budget), not only when one "
                         "fails.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method_module: MethodModuleOption = None,
) -> None:
    """Property-based checks of a metric (Finsler axioms, lowered forms, smoothness, solved
    distances) and of a policy (--run): a table with minimal counterexamples; exit 1 when a
    property fails (with --strict, also when one is inconclusive)."""
    from validation.testing import check

    m = metric_from_options(metric, metric_param, metric_module)
    try:
        if isinstance(examples, bool) or examples < 1:
            raise InputError(f"--examples must be a positive integer, got {examples}")
        if seed < 0:
            raise InputError(f"--seed must be a non-negative integer, got {seed}")
        if not 0.0 <= min_success <= 1.0:
            raise InputError(f"--min-success must be in [0, 1], got {min_success}")
        for opt, val in (("--max-length-ratio", max_length_ratio),
                         ("--midpoint-tol", midpoint_tol)):
            if not val > 0 or val == float("inf"):
                raise InputError(f"{opt} must be positive and finite, got {val}")
        if method_module:
            import learn

            learn.import_method_modules(method_module)
        policy = None
        if run is not None:
            import learn

            policy = learn.load_any_policy(run, checkpoint=checkpoint, env=m.name,
                                           metric_params=parse_metric_params(metric_param))
            if policy.metric != m:
                raise InputError(f"--run {run} is a policy for {policy.metric!r}, not for "
                                 f"{m!r}; give --metric-param as it was trained")
    except InputError as err:
        fail(str(err))
        return

    def progress(r: PropertyResult) -> None:
        if not as_json:
            typer.echo(f"  {r.name}: {r.status} ({r.seconds:.1f} s)", err=True)

    if not as_json:
        typer.echo(f"checking {m.name} (seed {seed}, {examples} examples per property)"
                   + (f" and the policy {run}" if run else ""), err=True)
    # hypothesis caches what it reads of the loaded modules under ./.hypothesis: keep the
    # user's folder clean (nothing written outside the declared outputs)
    from hypothesis.configuration import set_hypothesis_home_dir

    try:
        with tempfile.TemporaryDirectory(prefix="geodesics-check-") as home:
            set_hypothesis_home_dir(home)
            report = check(m, policy=policy, examples=examples, seed=seed,
                           midpoint_rtol=midpoint_tol, symmetry_rtol=midpoint_tol,
                           min_success=min_success, max_length_ratio=max_length_ratio,
                           progress=progress)
    except InputError as err:
        fail(str(err))
        return
    finally:
        set_hypothesis_home_dir(None)
    if as_json:
        typer.echo(json.dumps(report.to_dict(), indent=2))
    else:
        params = ", ".join(f"{k}={v!r}" for k, v in report.params.items())
        typer.echo(f"metric {m.name}({params})"
                   + (f", policy {report.policy}" if report.policy else "")
                   + f": seed {seed}, {examples} examples per property of F")
        typer.echo(report.table())
        typer.echo(f"\n{report.summary()} ({report.seconds:.1f} s)")
    code = report.exit_code(strict)
    if code:
        why = (f"{len(report.failed)} of {len(report.results)} properties failed, the root "
               f"cause first: {', '.join(r.name for r in report.failed)}" if report.failed
               else f"--strict and inconclusive: "
                    f"{', '.join(r.name for r in report.inconclusive)}")
        typer.echo(one_line(f"note: {why}"), err=True)
        raise typer.Exit(code=code)


def register(app: typer.Typer) -> None:
    """Add ``check`` to the ``geodesics`` app."""
    app.command("check")(check_command)
