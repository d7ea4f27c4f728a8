"""``geodesics train`` and ``geodesics evaluate``: thin CLI over `learn`.

Per-environment defaults (``learn.default_config``) are the settings of the shipped
policies; e.g. the shipped Matsumoto policy is reproduced by
``geodesics train --env matsumoto --out runs/matsumoto --seed 0``. Methods come from
`learn.registry` (``--method-module FILE.py`` imports a user's method first).
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

import finsler
from finsler.errors import InputError
from finsler.infra.files import check_input_dir, check_output_dir
from validation.cli.common import (
    MethodModuleOption,
    MetricModuleOption,
    MetricParamOption,
    TrainedMetricParamOption,
    fail,
    import_metric_modules,
    interrupted,
    json_text,
    output_path,
    parse_metric_params,
    parse_overrides,
)

__all__ = ["evaluate_command", "register", "train_command"]


def train_command(
    env: Annotated[str, typer.Option(help="Environment (metric) name, e.g. matsumoto.")],
    out: Annotated[Path, typer.Option(parser=output_path,
                                      help="Run directory to create (or resume).")],
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method: Annotated[str | None, typer.Option(
        help="A registered learning method: midpoint (eq. 6, default), inter (eq. 17), "
             "two-to-one (eq. 18), the paper's baselines seq (PPO, eqs. 14/57) and pg "
             "(policy gradient, eqs. 15/16), or one of --method-module.")] = None,
    method_module: MethodModuleOption = None,
    timesteps: Annotated[int | None, typer.Option(
        help="Budget of evaluations of C, all-inclusive: every evaluation the learner makes "
             "to learn (the validation evaluations that select checkpoints are not "
             "counted; default: the environment's default).")] = None,
    minutes: Annotated[float | None, typer.Option(
        help="Wall-clock limit in minutes (stops at whichever limit comes first).")] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (default 0).")] = None,
    device: Annotated[str, typer.Option(help="cpu or cuda.")] = "cpu",
    resume: Annotated[bool, typer.Option(
        "--resume", help="Continue the run in --out from its latest checkpoint.")] = False,
    paper: Annotated[bool, typer.Option(
        "--paper", help="Use the paper's appendix B.1 settings instead of the defaults.")
    ] = False,
    model_free: Annotated[bool, typer.Option(
        "--model-free", help="The model-free defaults: every term that differentiates C off "
                             "(values of C only, like the paper), Matsumoto 3 and car-like 2 "
                             "passes per collection.")] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    settings: Annotated[list[str] | None, typer.Option(
        "--set", metavar="FIELD=VALUE",
        help="Override any field of the method's config (learn.TrainConfig, SeqConfig / "
             "PGConfig for seq / pg, a user method's own; repeatable; VALUE is JSON or a "
             "bare string), e.g. --set path_energy_weight=0 --set hidden=[128,128].")
    ] = None,
) -> None:
    """Train a midpoint policy (Algorithm 1), or one of the paper's baselines, into a run
    directory (config.json, metrics.csv, checkpoints, result.json when finished).

    Counting: --timesteps and the metrics' `timesteps` column count EVERY evaluation of C
    made to learn (all-inclusive: trees, extra loss terms in every epoch, route search; not
    the validation evaluations that select checkpoints, the same for every method);
    `timesteps_paper` is the paper's count (trees only)
    and `timesteps_derivative` the evaluations whose derivative was used. Checkpoints are
    selected on a validation pair set, never on the default evaluation set.

    MODEL-FREE OR NOT: the paper's method uses values of C only, and so do the Matsumoto
    and Panda defaults. The car-like defaults add the path-energy actor term, which
    DIFFERENTIATES C (model-based); --model-free (or --paper) switches it off; config.json
    says which ("model_free").

    Defaults per environment (learn.default_config): full depth, lr 1e-3 cosine-decayed to
    5%, log1p critic targets, inputs scaled to [-1, 1], residual actor mean, collections
    of 16384 pairs, minibatches of 1024. matsumoto: 1e8 evaluations of C, 3 passes per
    collection, fused Adam, actor MLP 128-128-128, critic 64-64, the actor and the critic
    (log(c / r)) relative to each pair's length, model-free; carlike: one pass, path
    energy with p = 4, MLPs 128-128, 16 pairs per actor step and 4e8 (13.4x the trees'
    evaluations), the relative actor; panda-pole: 2e7 (the paper's budget), actor MLP
    256-256-256, critic 128-128 (symmetric), 3 epochs, eq. (6) as a power mean with p = 8
    (actor_loss_power), model-free.

    ANY METRIC: --metric-param NAME=VALUE sets the metric's parameters (recorded in
    config.json, used to evaluate, report and resume); --metric-module imports a user's
    module (or FILE.py) whose @finsler.register_metric classes are then trainable.
    """
    import learn

    try:
        params = _check_train_options(env, out, metric_param, metric_module, method_module,
                                      timesteps, minutes, device, resume)
        if resume:
            cfg = _resumed_config(out, env, method, seed, timesteps, minutes, device,
                                  settings or [], params)
        else:
            cfg = _new_config(env, method, paper, model_free, seed, timesteps, minutes,
                              device, settings or [], params)
        result = learn.train_run(cfg, out, resume=resume, progress=not quiet)
    except InputError as err:
        fail(str(err))
        return
    except learn.TrainingInterrupted as stop:
        interrupted(f"interrupted ({stop.signal_name}): the run is saved in {stop.run_dir} at "
                    f"{stop.timesteps} evaluations of C (iteration {stop.iterations}); resume "
                    f"with: geodesics train --env {env} --out {stop.run_dir} --resume"
                    + "".join(f" --metric-module {m}" for m in metric_module or [])
                    + "".join(f" --method-module {m}" for m in method_module or []))
    _print_trained(env, result)


def _check_train_options(env: str, out: Path, metric_param: list[str] | None,
                         metric_module: list[str] | None, method_module: list[str] | None,
                         timesteps: int | None, minutes: float | None, device: str,
                         resume: bool) -> dict[str, object] | None:
    """Step 1 of ``train``: the user's modules imported, the options checked; returns the
    parsed --metric-param values."""
    import learn

    import_metric_modules(metric_module)
    learn.import_method_modules(method_module)
    params = parse_metric_params(metric_param)
    check_output_dir(out, "--out")
    if not resume:  # a resumed run's config names (and re-imports) its metric
        finsler.registry.check_name(env, "environment")
    if timesteps is not None and timesteps < 1:
        raise InputError(f"--timesteps must be a positive integer, got {timesteps}")
    if minutes is not None and not minutes > 0:
        raise InputError(f"--minutes must be positive, got {minutes}")
    learn.resolve_device(device)
    return params


def _resumed_config(out: Path, env: str, method: str | None, seed: int | None,
                    timesteps: int | None, minutes: float | None, device: str,
                    settings: list[str], params: dict[str, object] | None) -> object:
    """Step 2 of ``train --resume``: the run's saved settings; explicitly given options must
    agree with them (the config's ``replace`` checks)."""
    import learn

    cfg = learn.load_run_config(out)
    if cfg.env != env:
        raise InputError(f"cannot resume: run {out} trains {cfg.env!r}, not {env!r}")
    given = {"method": method, "seed": seed, "timesteps": timesteps}
    over = {k: v for k, v in given.items() if v is not None}
    over.update(parse_settings(settings, type(cfg)))
    if params is not None:  # checked against the run's on resume
        over["metric_params"] = params
    return cfg.replace(minutes=minutes, device=device, **over)


def _print_trained(env: str, result: Any) -> None:
    """The one line ``train`` prints when the run finished."""
    f = result.final
    typer.echo(
        f"{env}: {result.timesteps} evaluations of C (all-inclusive) in "
        f"{result.wall_seconds:.1f} s ({f['evaluations_per_second']:.0f} evaluations of C/s); "
        f"validation success {f['success_rate']:.2%} (best {result.best['success_rate']:.2%}),"
        f" mean length {f['mean_length']:.4f}; run directory {result.run_dir}"
    )


def _new_config(env: str, method: str | None, paper: bool, model_free: bool,
                seed: int | None, timesteps: int | None, minutes: float | None,
                device: str, settings: list[str],
                metric_params: dict[str, object] | None = None) -> object:
    """The config of a new run from the command-line options: the method's default variant,
    or the variant of one of its presets (``--paper``, ``--model-free``)."""
    import learn

    method = method or "midpoint"
    entry = learn.get_method(method)
    flags = [f for f, on in (("paper", paper), ("model-free", model_free)) if on]
    if len(flags) > 1:
        raise InputError("--paper already is model-free; give one of --paper, --model-free")
    if flags and flags[0] not in entry.presets:
        raise InputError(f"--{flags[0]} applies to the midpoint learner, not --method "
                         f"{method} (its defaults are its own; --set FIELD=VALUE changes "
                         "them)")
    variant = entry.presets[flags[0]] if flags else entry.name
    cls = type(learn.make_config(env, variant))
    over = parse_settings(settings, cls)
    over.setdefault("method", method)
    if metric_params is not None:
        over["metric_params"] = metric_params
    return learn.make_config(env, variant, seed=0 if seed is None else seed,
                            timesteps=timesteps, minutes=minutes, device=device, **over)


def parse_settings(items: list[str], cls: type | None = None) -> dict[str, object]:
    """``["field=value", ...]`` -> overrides of fields of the config class ``cls``
    (default [`learn.TrainConfig`][learn.TrainConfig]; values parsed as JSON, else kept as strings);
    unknown or run-control fields are an error."""
    import dataclasses
    import difflib

    import learn

    names = [f.name for f in dataclasses.fields(cls or learn.TrainConfig)]
    reserved = {"env": "--env", "device": "--device", "minutes": "--minutes",
                "seed": "--seed", "timesteps": "--timesteps", "method": "--method",
                "metric_params": "--metric-param NAME=VALUE",
                "metric_class": "--metric-module MODULE"}
    for item in items:  # the run-control fields have options of their own
        key = item.partition("=")[0].strip()
        if key in reserved:
            raise InputError(f"--set {key}=... is not allowed; use {reserved[key]}")
    out = parse_overrides(items)
    for key in out:
        if key not in names:
            close = difflib.get_close_matches(key, names, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise InputError(f"--set: unknown config field {key!r}{hint}")
    return out


def evaluate_command(
    run: Annotated[Path | None, typer.Option(help="Run directory written by `train`.")] = None,
    env: Annotated[str | None, typer.Option(
        help="Environment: evaluates its shipped policy (unless --run is given).")] = None,
    pairs: Annotated[Path | None, typer.Option(
        help="PAIRS.npy of shape (K, 2, dim); default: the environment's 100 default "
             "evaluation pairs (no shipped policy's checkpoint was selected on them; older "
             "runs' were, and the output says so for such a policy).")] = None,
    eps: Annotated[float | None, typer.Option(help="Success threshold (default: task's).")
                   ] = None,
    depth: Annotated[int | None, typer.Option(help="Tree depth D (default: task's).")] = None,
    checkpoint: Annotated[str, typer.Option(
        help="best (selected on the validation set during training; for runs older "
             "than that set, on the default evaluation set) or latest (the last one, no "
             "selection).")] = "best",
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    metric_param: TrainedMetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method_module: MethodModuleOption = None,
    search: Annotated[bool, typer.Option(
        "--search", help="Evaluate the paths of the route search (learn.midpoint.search: candidate "
        "midpoints at the top levels chosen by the cost of the policy's completed paths, "
        "values of C only) instead of the plain recursive generation.")] = False,
) -> None:
    """Evaluate a trained policy (section 5.1): success rate, mean length, max segment cost.

    The default pairs are the environment's default evaluation set. A run trained today
    never sees it (its checkpoints are selected on a separate validation set), nor did the
    shipped policies' runs; a run older than the validation set had its best checkpoint
    selected on it, so its figures there are optimistic (the output says so): give --pairs
    of a fresh seed for honest ones. The output names the checkpoint file used."""
    import numpy as np

    import learn

    try:
        import_metric_modules(metric_module)
        learn.import_method_modules(method_module)
        params = parse_metric_params(metric_param)
        if run is None and env is None:
            raise InputError("give --run DIR or --env NAME")
        if checkpoint not in ("best", "latest"):
            raise InputError(f"--checkpoint must be best or latest, got {checkpoint!r}")
        if run is not None:
            check_input_dir(run, "--run")
            policy = learn.load_any_policy(run, checkpoint=checkpoint, env=env,
                                     metric_params=params)
        else:
            finsler.registry.check_name(env, "environment")
            if env not in learn.shipped_policies():
                raise InputError(f"no shipped policy for {env!r}; shipped: "
                                 f"{', '.join(learn.shipped_policies())}; train one with "
                                 "`geodesics train` and pass --run")
            policy = learn.load_policy(env, checkpoint=checkpoint, metric_params=params)
        if eps is not None and not (np.isfinite(eps) and eps > 0):
            raise InputError(f"--eps must be positive and finite, got {eps}")
        if depth is not None and depth < 0:
            raise InputError(f"--depth must be a non-negative integer, got {depth}")
        p = finsler.load_pairs(pairs, policy.metric, "--pairs") if pairs is not None else None
        searched = None
        if search:
            if not callable(getattr(policy, "search", None)):
                raise InputError(f"--search needs a midpoint policy; {policy.source} is a "
                                 f"{type(policy).__name__}")
            pp = p if p is not None else finsler.default_pairs(policy.metric)
            searched = policy.search(pp[:, 0], pp[:, 1], depth=depth, eps=eps)
            res = learn.evaluate_paths(policy.metric, searched.paths,
                                       policy.eps if eps is None else eps)
        else:
            res = policy.evaluate(p, eps=eps, depth=depth)
    except InputError as err:
        fail(str(err))
        return
    mp = getattr(policy.config, "metric_params", None) or {}
    note = None
    if run is None and pairs is None and checkpoint == "best":
        from validation.report import selected_on_default_set

        if selected_on_default_set(policy):
            note = ("the shipped policy's checkpoint was selected on these default evaluation "
                    "pairs: the figures are optimistic; give --pairs of a fresh seed")
        else:
            note = ("the shipped policy's checkpoint was selected on the validation set, not "
                    "on these pairs; figures on pairs of a fresh seed are in "
                    "learn/policies/README.md")
    out = {"env": policy.metric.name, "metric_params": mp, "source": policy.source,
           "checkpoint": policy.checkpoint, "pairs_note": note, **res.to_dict()}
    if searched is not None:
        out["search"] = {**learn.SearchSpec().to_dict(),
                         "evaluations_of_C_per_path": searched.evaluations_per_path}
    if as_json:
        typer.echo(json_text(out))
        return
    typer.echo(f"policy      {policy.source} ({policy.checkpoint})")
    typer.echo(f"environment {policy.metric.name}  depth {res.depth}  eps {res.eps:g}  "
               f"pairs {len(res.success)}")
    if mp:
        typer.echo("parameters  " + ", ".join(f"{k}={v}" for k, v in mp.items()))
    if searched is not None:
        typer.echo(f"paths       route search ({searched.evaluations_per_path:.0f} evaluations "
                   "of C per path, values only)")
    typer.echo(f"success     {res.success_rate:.2%}")
    typer.echo(f"mean length {res.mean_length:.6g}")
    typer.echo(f"mean max segment cost {res.mean_max_segment_cost:.6g}")
    if note is not None:
        typer.echo(f"note        {note}")


def register(app: typer.Typer) -> None:
    """Add ``train`` and ``evaluate`` to the ``geodesics`` app."""
    app.command("train")(train_command)
    app.command("evaluate")(evaluate_command)
