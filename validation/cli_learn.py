"""``geodesics train`` and ``geodesics evaluate``: thin CLI over :mod:`learn`.

Per-environment defaults (``learn.default_config``) are the settings of the shipped
policies; e.g. the shipped Matsumoto policy is reproduced by
``geodesics train --env matsumoto --out runs/matsumoto --seed 0``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import numpy as np
import typer

import finsler
from finsler.errors import InputError

__all__ = ["evaluate_command", "register", "train_command"]


def _fail(message: str) -> None:
    from validation.cli import fail

    fail(message)


def train_command(
    env: Annotated[str, typer.Option(help="Environment (metric) name, e.g. matsumoto.")],
    out: Annotated[Path, typer.Option(help="Run directory to create (or resume).")],
    method: Annotated[str | None, typer.Option(
        help="Actor loss: midpoint (eq. 6, default), inter (eq. 17) or two-to-one (eq. 18).")
    ] = None,
    timesteps: Annotated[int | None, typer.Option(
        help="Budget of evaluations of C (default: the environment's default).")] = None,
    minutes: Annotated[float | None, typer.Option(
        help="Wall-clock limit in minutes (stops at whichever limit comes first).")] = None,
    seed: Annotated[int | None, typer.Option(help="Random seed (default 0).")] = None,
    device: Annotated[str, typer.Option(help="cpu or cuda.")] = "cpu",
    resume: Annotated[bool, typer.Option(
        "--resume", help="Continue the run in --out from its latest checkpoint.")] = False,
    paper: Annotated[bool, typer.Option(
        "--paper", help="Use the paper's appendix B.1 settings instead of the defaults.")
    ] = False,
    quiet: Annotated[bool, typer.Option("--quiet", help="No progress bar.")] = False,
    settings: Annotated[list[str] | None, typer.Option(
        "--set", metavar="FIELD=VALUE",
        help="Override any field of learn.TrainConfig (repeatable; VALUE is JSON or a "
             "bare string), e.g. --set path_energy_weight=0 --set hidden=[128,128].")
    ] = None,
) -> None:
    """Train a midpoint policy (Algorithm 1) into a run directory.

    Defaults per environment (learn.default_config; the settings of the shipped policies):
    all at full depth, lr 1e-3 cosine-decayed to 5%, log1p critic targets, inputs scaled
    to [-1, 1], residual actor mean, collections of 16384 pairs, minibatches of 1024.
    matsumoto: 6e7 timesteps, one pass per collection, fused Adam and the path-energy
    actor term (weight 1, 16 fresh pairs per actor step); carlike: the same with MLPs
    128-128 and 3e7 timesteps; panda-pole: 1e7 timesteps, MLPs 128-128, symmetric critic,
    3 epochs, no path energy. config.json in the run directory lists every choice beyond
    the paper; --set FIELD=VALUE overrides any of them.
    """
    import learn

    try:
        if env not in finsler.list_metrics():
            raise finsler.UnknownMetricError(
                f"unknown environment {env!r}; known: {', '.join(finsler.list_metrics())}")
        if timesteps is not None and timesteps < 1:
            raise InputError(f"--timesteps must be a positive integer, got {timesteps}")
        if minutes is not None and not minutes > 0:
            raise InputError(f"--minutes must be positive, got {minutes}")
        learn.resolve_device(device)
        given: dict[str, object] = {"method": method, "seed": seed, "timesteps": timesteps}
        over = {k: v for k, v in given.items() if v is not None}
        over.update(parse_settings(settings or []))
        if resume:
            # the run's saved settings; explicitly given options must agree with them
            cfg = learn.read_run_config(out).replace(minutes=minutes, device=device)
            if cfg.env != env:
                raise InputError(f"cannot resume: run {out} trains {cfg.env!r}, not {env!r}")
            cfg = cfg.replace(**over)
        else:
            base = learn.paper_config if paper else learn.default_config
            cfg = base(env, minutes=minutes, device=device, **over)
        result = learn.train(cfg, out, resume=resume, progress=not quiet)
    except InputError as err:
        _fail(str(err))
        return
    f = result.final
    typer.echo(
        f"{env}: {result.timesteps} timesteps in {result.wall_seconds:.1f} s "
        f"({f['timesteps_per_second']:.0f} timesteps/s); success {f['success_rate']:.2%} "
        f"(best {result.best['success_rate']:.2%}), mean length {f['mean_length']:.4f}; "
        f"run directory {result.run_dir}"
    )



def parse_settings(items: list[str]) -> dict[str, object]:
    """``["field=value", ...]`` -> overrides of :class:`learn.TrainConfig` fields (values
    parsed as JSON, else kept as strings); unknown or run-control fields are an error."""
    import dataclasses
    import difflib

    import learn

    names = [f.name for f in dataclasses.fields(learn.TrainConfig)]
    reserved = {"env": "--env", "device": "--device", "minutes": "--minutes"}
    out: dict[str, object] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        key = key.strip()
        if not sep or not key:
            raise InputError(f"--set expects FIELD=VALUE, got {item!r}")
        if key in reserved:
            raise InputError(f"--set {key}=... is not allowed; use {reserved[key]}")
        if key not in names:
            close = difflib.get_close_matches(key, names, n=3)
            hint = f" (did you mean {', '.join(close)}?)" if close else ""
            raise InputError(f"--set: unknown config field {key!r}{hint}")
        try:
            value = json.loads(raw)
        except json.JSONDecodeError:
            value = raw
        if isinstance(value, list):
            value = tuple(value)
        out[key] = value
    return out


def evaluate_command(
    run: Annotated[Path | None, typer.Option(help="Run directory written by `train`.")] = None,
    env: Annotated[str | None, typer.Option(
        help="Environment: evaluates its shipped policy (unless --run is given).")] = None,
    pairs: Annotated[Path | None, typer.Option(
        help="PAIRS.npy of shape (K, 2, dim); default: the environment's 100 default "
             "evaluation pairs.")] = None,
    eps: Annotated[float | None, typer.Option(help="Success threshold (default: task's).")
                   ] = None,
    depth: Annotated[int | None, typer.Option(help="Tree depth D (default: task's).")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
) -> None:
    """Evaluate a trained policy (section 5.1): success rate, mean length, max segment cost."""
    import learn

    try:
        if run is None and env is None:
            raise InputError("give --run DIR or --env NAME")
        if run is not None:
            if not run.is_dir():
                raise InputError(f"run directory {run} does not exist")
            policy = learn.load_policy(run, env=env)
        else:
            if env not in finsler.list_metrics():
                raise finsler.UnknownMetricError(
                    f"unknown environment {env!r}; known: {', '.join(finsler.list_metrics())}")
            if env not in learn.shipped_policies():
                raise InputError(f"no shipped policy for {env!r}; shipped: "
                                 f"{', '.join(learn.shipped_policies())}; train one with "
                                 "`geodesics train` and pass --run")
            policy = learn.load_policy(env)
        if eps is not None and not (np.isfinite(eps) and eps > 0):
            raise InputError(f"--eps must be positive and finite, got {eps}")
        if depth is not None and depth < 0:
            raise InputError(f"--depth must be a non-negative integer, got {depth}")
        p = finsler.load_pairs(pairs, policy.metric) if pairs is not None else None
        res = policy.evaluate(p, eps=eps, depth=depth)
    except InputError as err:
        _fail(str(err))
        return
    out = {"env": policy.metric.name, "source": policy.source, **res.to_dict()}
    if as_json:
        typer.echo(json.dumps(out, indent=2))
        return
    typer.echo(f"policy      {policy.source}")
    typer.echo(f"environment {policy.metric.name}  depth {res.depth}  eps {res.eps:g}  "
               f"pairs {len(res.success)}")
    typer.echo(f"success     {res.success_rate:.2%}")
    typer.echo(f"mean length {res.mean_length:.6g}")
    typer.echo(f"mean max segment cost {res.mean_max_segment_cost:.6g}")


def register(app: typer.Typer) -> None:
    """Add ``train`` and ``evaluate`` to the ``geodesics`` app."""
    app.command("train")(train_command)
    app.command("evaluate")(evaluate_command)
