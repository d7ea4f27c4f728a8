"""A solved path to look at and to take away: `plot_geodesic` draws one solved path
(`validation.figures.geodesic_path`) and `export_paths` writes one or many as CSV, ``.npy``
or JSON. ``geodesics solve --plot FILE.png --out FILE.csv|.npy|.json`` calls them.

File contents (``dim`` coordinates, ``n`` segments, ``K`` pairs):

- ``.csv``: one pair: a header ``x0,x1,...`` (the domain's coordinate names) and ``n+1``
  rows; several pairs: the columns ``pair,point`` first, ``K * (n+1)`` rows (sizes may
  differ per pair with ``--tol``).
- ``.npy``: one pair ``(n+1, dim)``; several ``(K, n+1, dim)`` (one size for all pairs).
- ``.json``: each result's ``to_dict()`` (one object, or a list for several).
"""

from __future__ import annotations

import io
import json
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from finsler.errors import InputError

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from finsler import Metric
    from solvers import GeodesicResult

__all__ = ["FIGURE_FORMATS", "PATH_FORMATS", "export_paths", "path_bytes", "plot_geodesic"]

#: Suffixes `export_paths` writes (``--out``).
PATH_FORMATS = (".csv", ".npy", ".json")
#: Suffixes `plot_geodesic` writes (``--plot``).
FIGURE_FORMATS = (".png", ".pdf", ".svg")


def _points(item: Any) -> np.ndarray:
    """``(n+1, dim)`` points of a result (its ``points``) or of an array."""
    return np.asarray(getattr(item, "points", item), dtype=float)


def _names(metric: Metric | None, dim: int) -> list[str]:
    names = list(metric.domain.names) if metric is not None else []
    return names if len(names) == dim else [f"x{j}" for j in range(dim)]


def check_suffix(path: str | Path, formats: Sequence[str], option: str) -> Path:
    """``path`` as a Path if its suffix is one of ``formats``, else an InputError naming
    ``option``."""
    path = Path(path)
    if path.suffix.lower() not in formats:
        raise InputError(f"{option} {path}: the file must end in {', '.join(formats)}")
    return path


def path_bytes(results: Any, suffix: str, metric: Metric | None = None) -> bytes:
    """The content `export_paths` writes for ``suffix`` (``.csv``, ``.npy`` or ``.json``).

    ``results``: one `solvers.GeodesicResult` or ``(n+1, dim)`` array, or a sequence of
    them (several pairs); ``metric`` names the CSV columns (else ``x0``, ``x1``, ...)."""
    if isinstance(results, (list, tuple)):
        one, items = False, list(results)
    else:
        one = hasattr(results, "points") or np.ndim(results) == 2
        items = [results] if one else list(results)
    if not items:
        raise InputError("no path to write")
    paths = [_points(r) for r in items]
    dim = paths[0].shape[1]
    suffix = suffix.lower()
    if suffix == ".json":
        rows = [r.to_dict() if hasattr(r, "to_dict") else {"points": p.tolist()}
                for r, p in zip(items, paths)]
        from validation.jsonout import jsonable

        return json.dumps(jsonable(rows[0] if one else rows), indent=2,
                          allow_nan=False).encode()
    if suffix == ".npy":
        sizes = {len(p) for p in paths}
        if len(sizes) > 1:
            raise InputError(f"the paths have {len(sizes)} different sizes (with --tol each "
                             "pair stops at its own): .npy holds one array; use .csv or "
                             ".json")
        buf = io.BytesIO()
        np.save(buf, paths[0] if one else np.stack(paths))
        return buf.getvalue()
    if suffix == ".csv":
        names = _names(metric, dim)
        lines = [",".join(names if one else ["pair", "point", *names])]
        for k, p in enumerate(paths):
            for i, row in enumerate(p):
                cells = [repr(float(v)) for v in row]
                lines.append(",".join(cells if one else [str(k), str(i), *cells]))
        return ("\n".join(lines) + "\n").encode()
    raise InputError(f"a path file must end in {', '.join(PATH_FORMATS)}, got {suffix!r}")


def export_paths(results: Any, path: str | Path, metric: Metric | None = None) -> Path:
    """Write one solved path or several to ``path`` (``.csv``, ``.npy`` or ``.json``, from
    its suffix; see the module docstring), atomically. Returns the path."""
    from finsler.infra.files import atomic_write_bytes

    path = check_suffix(path, PATH_FORMATS, "path file")
    return atomic_write_bytes(path, path_bytes(results, path.suffix, metric), "path file")


def plot_geodesic(metric: Metric, result: GeodesicResult | Any, path: str | Path | None = None,
                  dpi: int = 120) -> Figure:
    """The figure of one solved path (`validation.figures.geodesic_path`: 2-D over a map
    of the metric, 3-D its projection and coordinates against arc length, arms the joint
    angles and the end effector's path); written atomically to ``path`` (``.png``,
    ``.pdf`` or ``.svg``) if given. ``result``: a `solvers.GeodesicResult` or an
    ``(n+1, dim)`` array."""
    from validation import figures as fg

    target = None if path is None else check_suffix(path, FIGURE_FORMATS, "figure file")
    fig = fg.geodesic_path(metric, _points(result))
    if target is not None:
        from finsler.infra.files import atomic_write_bytes

        atomic_write_bytes(target, fg.figure_bytes(fig, target.suffix.lower()[1:], dpi),
                           "figure file")
    return fig
