"""Helpers shared by the ``geodesics`` commands: clear one-line errors (exit code 2),
point parsing and metric look-up. The command modules import this, never ``cli``."""

from __future__ import annotations

import json
from typing import Any

import numpy as np
import typer

import finsler
from finsler.errors import InputError

__all__ = ["fail", "metric_or_fail", "parse_overrides", "parse_point"]


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


def metric_or_fail(name: str) -> finsler.Metric:
    try:
        return finsler.get_metric(name)
    except InputError as err:
        fail(str(err))
        raise  # unreachable


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
