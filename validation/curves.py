"""Learning curves of a sweep: mean +- standard error over seeds (the numbers of Fig. 2).

A *sweep directory* (written by ``geodesics sweep``) holds one run directory per
environment, variant and seed::

    DIR/<env>/<variant>/seed-<s>/{config.json, metrics.csv, ...}

Environment and variant names are opaque strings (``midpoint``, ``paper``, ``seq``, ...),
ordered by sorting. Only directories named ``seed-<integer>`` two levels below an
environment directory are runs; files and other directories are ignored.

Conventions of `learning_curves` (each seed's log is a step function of ``x``):

* the value of a seed at ``x`` is its **last evaluation at or before** ``x`` (for equal
  ``x``, the later row of the log);
* a seed **contributes only between its first and its last evaluation**: before its first
  evaluation it has no value (nothing is invented; in practice every run evaluates at
  ``timesteps = 0``, so this only matters for wall time, where the first evaluation comes
  a few milliseconds in), and after its last evaluation it has stopped. ``n_seeds`` says
  how many seeds every grid point averages; ``n_seeds = 0`` gives ``mean = stderr = NaN``;
* ``stderr = std(values, ddof=1) / sqrt(n)``; with **one seed it is NaN** (undefined, so
  no band is drawn), never 0;
* the default grid is every evaluation point plus ``np.nextafter(last, inf)`` for each
  seed that stops before the longest one, so the mean between grid points is exactly the
  value at the grid point on the left.

`running_mean_threshold` is the "first time the running mean of 5 consecutive
evaluations reaches a threshold" used in reports.
"""

from __future__ import annotations

import csv
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from finsler.errors import InputError

__all__ = [
    "METRICS_FILE",
    "X_KINDS",
    "Crossing",
    "Curve",
    "Run",
    "Sweep",
    "curves_csv",
    "learning_curves",
    "read_run_metrics",
    "read_sweep",
    "running_mean_threshold",
]

METRICS_FILE = "metrics.csv"  # the run-directory contract's name (learn.storage.METRICS_FILE)
#: The x axes a learning curve can use: all-inclusive evaluations of C, or wall time.
X_KINDS = ("timesteps", "wall_seconds")
_SEED_DIR = re.compile(r"seed-(\d+)")


# ----------------------------------------------------------------------------------------
# reading a sweep
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Run:
    """One run directory of a sweep and its parsed metrics log.

    ``rows`` are the rows of ``metrics.csv`` in file order, numbers parsed to int/float
    (other cells kept as strings); every row has the header's columns, and ``timesteps``
    and ``wall_seconds`` are finite and non-decreasing."""

    env: str
    variant: str
    seed: int
    path: Path
    rows: tuple[dict[str, Any], ...]

    @property
    def metrics_file(self) -> Path:
        return self.path / METRICS_FILE

    def values(self, column: str) -> np.ndarray:
        """Column ``column`` of the log as float64, shape ``(E,)`` (E evaluations); an
        InputError naming the file if the column is absent or a cell is not a finite
        number."""
        if column not in self.rows[0]:
            raise InputError(f"{self.metrics_file} has no column {column!r} (columns: "
                             f"{', '.join(self.rows[0])})")
        out = np.empty(len(self.rows), dtype=np.float64)
        for i, r in enumerate(self.rows):
            v = r[column]
            if isinstance(v, str) or not math.isfinite(float(v)):
                raise InputError(f"{self.metrics_file}: row {i + 1}, column {column!r} is "
                                 f"{v!r}, not a finite number")
            out[i] = float(v)
        return out


@dataclass(frozen=True)
class Sweep:
    """All runs of a sweep directory: ``runs[(env, variant)]`` is the tuple of that
    variant's runs sorted by seed; keys are sorted (env first, then variant)."""

    root: Path
    runs: Mapping[tuple[str, str], tuple[Run, ...]]

    @property
    def envs(self) -> list[str]:
        """Environments, sorted."""
        return sorted({e for e, _ in self.runs})

    def variants(self, env: str | None = None) -> list[str]:
        """Variants of ``env`` (all environments if None), sorted."""
        return sorted({v for e, v in self.runs if env is None or e == env})

    def __len__(self) -> int:
        """Number of runs."""
        return sum(len(r) for r in self.runs.values())


def _parse_cell(v: str) -> Any:
    try:
        return int(v)
    except ValueError:
        try:
            return float(v)
        except ValueError:
            return v


def read_run_metrics(path: Path) -> tuple[dict[str, Any], ...]:
    """Rows of a run's ``metrics.csv``, checked: an InputError naming the file if it is
    missing, not UTF-8 text, has no header or no rows, has a row with missing or extra
    cells, or lacks finite non-decreasing ``timesteps`` / ``wall_seconds``."""
    path = Path(path)
    if not path.is_file():
        raise InputError(f"{path} is missing (every run directory of a sweep needs its "
                         "metrics log)")
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as err:
        raise InputError(f"{path} is corrupt: not UTF-8 text ({err})") from err
    except OSError as err:
        raise InputError(f"{path} cannot be read: {err}") from err
    try:
        table = list(csv.reader(text.splitlines()))
    except csv.Error as err:
        raise InputError(f"{path} is corrupt: not CSV ({err})") from err
    table = [t for t in table if t]  # blank lines
    if not table or not any(c.strip() for c in table[0]):
        raise InputError(f"{path} is corrupt: empty, no header row")
    header = [c.strip() for c in table[0]]
    if len(set(header)) != len(header):
        raise InputError(f"{path} is corrupt: repeated column names in the header")
    for need in X_KINDS:
        if need not in header:
            raise InputError(f"{path} is corrupt: no column {need!r} (columns: "
                             f"{', '.join(header)})")
    if len(table) == 1:
        raise InputError(f"{path} has a header but no evaluation rows")
    rows = []
    for i, cells in enumerate(table[1:], start=1):
        if len(cells) != len(header):
            raise InputError(f"{path} is corrupt: row {i} has {len(cells)} cells, the "
                             f"header has {len(header)}")
        rows.append({k: _parse_cell(c.strip()) for k, c in zip(header, cells)})
    for col in X_KINDS:
        prev = -math.inf
        for i, r in enumerate(rows, start=1):
            v = r[col]
            if isinstance(v, str) or not math.isfinite(float(v)):
                raise InputError(f"{path} is corrupt: row {i}, column {col!r} is {v!r}, "
                                 "not a finite number")
            if float(v) < prev:
                raise InputError(f"{path} is corrupt: column {col!r} decreases at row {i} "
                                 f"({prev:g} -> {float(v):g})")
            prev = float(v)
    return tuple(rows)


def read_sweep(directory: str | Path) -> Sweep:
    """Read every run ``DIR/<env>/<variant>/seed-<s>/`` of a sweep directory.

    Raises InputError (naming the path) if ``directory`` does not exist or holds no run,
    if a directory is named ``seed-`` without an integer, or if a run's ``metrics.csv`` is
    missing or corrupt (see `read_run_metrics`)."""
    root = Path(directory)
    if not root.exists():
        raise InputError(f"sweep directory {root} does not exist")
    if not root.is_dir():
        raise InputError(f"{root} is not a directory (expected a sweep directory "
                         "DIR/<env>/<variant>/seed-<s>/)")
    runs: dict[tuple[str, str], list[Run]] = {}
    for env_dir in _subdirs(root):
        for var_dir in _subdirs(env_dir):
            for seed_dir in _subdirs(var_dir):
                if not seed_dir.name.startswith("seed-"):
                    continue
                m = _SEED_DIR.fullmatch(seed_dir.name)
                if m is None:
                    raise InputError(f"{seed_dir}: a run directory's name must be "
                                     "seed-<non-negative integer>")
                rows = read_run_metrics(seed_dir / METRICS_FILE)
                runs.setdefault((env_dir.name, var_dir.name), []).append(
                    Run(env_dir.name, var_dir.name, int(m.group(1)), seed_dir, rows))
    if not runs:
        raise InputError(f"no runs in {root}: expected run directories "
                         f"{root}/<env>/<variant>/seed-<s>/ holding metrics.csv")
    for key, lst in runs.items():
        seeds = [r.seed for r in lst]
        if len(set(seeds)) != len(seeds):  # seed-1 and seed-01
            raise InputError(f"{root}/{key[0]}/{key[1]}: the same seed appears twice "
                             f"({sorted(r.path.name for r in lst)})")
    return Sweep(root, {k: tuple(sorted(runs[k], key=lambda r: r.seed))
                        for k in sorted(runs)})


def _subdirs(p: Path) -> list[Path]:
    return sorted(c for c in p.iterdir() if c.is_dir() and not c.name.startswith("."))


# ----------------------------------------------------------------------------------------
# mean +- standard error over seeds
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Curve:
    """Mean +- standard error over seeds of one (env, variant) on a grid of ``x``.

    ``x``, ``mean``, ``stderr``: float64 ``(G,)``; ``n_seeds``: int64 ``(G,)``, the number
    of seeds whose first evaluation is at or before ``x`` and whose last is at or after
    it. ``stderr`` is NaN where ``n_seeds < 2``; ``mean`` is NaN where ``n_seeds == 0``."""

    env: str
    variant: str
    x_kind: str
    column: str
    x: np.ndarray
    mean: np.ndarray
    stderr: np.ndarray
    n_seeds: np.ndarray
    seeds: tuple[int, ...]


def step_values(xs: np.ndarray, ys: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """A seed's step function on ``grid``: ``ys[j]`` for the last ``j`` with
    ``xs[j] <= g`` (``xs`` non-decreasing, shape ``(E,)``); NaN before ``xs[0]`` and after
    ``xs[-1]``. Returns ``(G,)`` float64."""
    idx = np.searchsorted(xs, grid, side="right") - 1
    out = ys[np.clip(idx, 0, len(ys) - 1)].astype(np.float64)
    out[(grid < xs[0]) | (grid > xs[-1])] = np.nan
    return out


def _grid(grid: Any, xs: Sequence[np.ndarray]) -> np.ndarray:
    if grid is None:  # evaluation points and seed ends: exact for the step means
        ends = np.array([float(x[-1]) for x in xs])
        ends = np.nextafter(ends[ends < ends.max()], np.inf)
        return np.unique(np.concatenate([*xs, ends]))
    if isinstance(grid, (int, np.integer)) and not isinstance(grid, bool):
        if grid < 2:
            raise InputError(f"grid: need at least 2 points, got {grid}")
        lo = min(float(x[0]) for x in xs)
        hi = max(float(x[-1]) for x in xs)
        return np.linspace(lo, hi, int(grid))
    g = np.asarray(grid, dtype=np.float64)
    if g.ndim != 1 or g.size == 0 or not np.all(np.isfinite(g)):
        raise InputError("grid: expected None, a number of points, or a non-empty 1-D "
                         "array of finite x values")
    if np.any(np.diff(g) <= 0):
        raise InputError("grid: x values must be strictly increasing")
    return g


def learning_curves(
    sweep: Sweep,
    x: str = "timesteps",
    column: str = "success_rate",
    grid: int | Sequence[float] | np.ndarray | None = None,
) -> dict[tuple[str, str], Curve]:
    """Per (env, variant), mean and standard error over seeds of ``column`` against ``x``
    (``"timesteps"``: all-inclusive evaluations of C; ``"wall_seconds"``: wall time).

    ``grid``: None (default) = the union of the seeds' evaluation points, plus, for every
    seed whose log ends before the longest one, the next float after its last evaluation
    (``np.nextafter(last, inf)``: from there on the mean no longer includes that seed); the
    mean is a step function that is constant between consecutive points of this grid, so
    a ``steps-post`` plot of it is exact. An int G = G evenly spaced points from the
    earliest first evaluation to the latest last evaluation of that (env, variant); or an
    array ``(G,)`` of strictly increasing x values used for every (env, variant).
    Conventions (step values, seeds outside their evaluated range, NaN standard error for
    one seed): module docstring."""
    if x not in X_KINDS:
        raise InputError(f"x must be one of {', '.join(X_KINDS)}, got {x!r}")
    out: dict[tuple[str, str], Curve] = {}
    for key, runs in sweep.runs.items():
        xs = [r.values(x) for r in runs]
        ys = [r.values(column) for r in runs]
        g = _grid(grid, xs)
        vals = np.stack([step_values(a, b, g) for a, b in zip(xs, ys)])  # (S, G)
        have = np.isfinite(vals)
        n = have.sum(axis=0)
        with np.errstate(invalid="ignore", divide="ignore"):
            total = np.where(have, vals, 0.0).sum(axis=0)
            mean = np.where(n > 0, total / np.maximum(n, 1), np.nan)
            dev2 = np.where(have, (vals - mean) ** 2, 0.0).sum(axis=0)
            std = np.sqrt(dev2 / np.maximum(n - 1, 1))
            stderr = np.where(n >= 2, std / np.sqrt(np.maximum(n, 1)), np.nan)
        out[key] = Curve(key[0], key[1], x, column, g, mean, stderr, n.astype(np.int64),
                         tuple(r.seed for r in runs))
    return out


def curves_csv(curves: Iterable[Curve]) -> str:
    """CSV text with columns ``env, variant, x_kind, x, mean, stderr, n_seeds`` (one row
    per grid point, numbers at full precision, NaN written as ``nan``)."""
    lines = ["env,variant,x_kind,x,mean,stderr,n_seeds"]
    for c in curves:
        for i in range(len(c.x)):
            cells = [c.env, c.variant, c.x_kind, repr(float(c.x[i])), repr(float(c.mean[i])),
                     repr(float(c.stderr[i])), str(int(c.n_seeds[i]))]
            lines.append(",".join(_csv_cell(s) for s in cells))
    return "\n".join(lines) + "\n"


def _csv_cell(s: str) -> str:
    if any(ch in s for ch in ',"\n\r'):
        return '"' + s.replace('"', '""') + '"'
    return s


# ----------------------------------------------------------------------------------------
# when does a run reach a threshold?
# ----------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Crossing:
    """Where a running mean first reaches a threshold: the evaluation closing the window
    (``index`` into the rows, 0-based), its ``timesteps`` (all-inclusive evaluations of C),
    ``wall_seconds``, and the running mean there."""

    index: int
    timesteps: float
    wall_seconds: float
    running_mean: float


def running_mean_threshold(
    rows: Sequence[Mapping[str, Any]],
    threshold: float,
    window: int = 5,
    column: str = "success_rate",
) -> Crossing | None:
    """The first evaluation at which the mean of ``column`` over the last ``window``
    consecutive evaluations (this one and the ``window - 1`` before it) is ``>=
    threshold``; None if that never happens (or there are fewer than ``window`` rows).

    ``rows``: metrics rows in log order (`Run.rows` or
    ``learn.storage.read_metrics``), each with ``column``, ``timesteps`` and
    ``wall_seconds``. The comparison allows a relative 1e-12 for rounding (five
    evaluations at 0.9 reach 0.9)."""
    if window < 1:
        raise InputError(f"window must be >= 1, got {window}")
    threshold = float(threshold)
    if not math.isfinite(threshold):
        raise InputError(f"threshold must be finite, got {threshold}")
    vals = []
    for i, r in enumerate(rows):
        try:
            vals.append(float(r[column]))
        except (KeyError, TypeError, ValueError) as err:
            raise InputError(f"metrics row {i}: no numeric {column!r} ({err})") from err
    tol = 1e-12 * max(1.0, abs(threshold))
    for end in range(window - 1, len(vals)):
        m = math.fsum(vals[end - window + 1:end + 1]) / window
        if m >= threshold - tol:
            r = rows[end]
            return Crossing(end, float(r["timesteps"]), float(r["wall_seconds"]), m)
    return None
