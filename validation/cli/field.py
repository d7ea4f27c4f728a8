"""``geodesics field``: the distance from one source over the whole domain (a grid of
values and a figure), and the distance, error estimate and geodesic to ``--goal`` points.

Writes ``DIR/field.npy`` (the grid values, ``inf`` outside the domain), ``DIR/error.npy``
(the error estimates), ``DIR/field.json`` (the grid's nodes: ``low``, ``spacing``,
``shape``; the summary; one row per goal) and ``DIR/field.png`` (2-D: filled contours
with the geodesics to the goals; 3-D: slices at a few values of the last coordinate).
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Any

import typer

from finsler.errors import InputError
from validation.cli.common import (
    MetricModuleOption,
    MetricParamOption,
    fail,
    interrupted,
    metric_from_options,
    parse_point,
)

__all__ = ["field_command", "register"]


def _figure(f: Any, geodesics: list[Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    axes = f.grid.axes()
    names = list(f.metric.domain.names) or [f"x{i}" for i in range(f.metric.dim)]
    vals = np.where(np.isfinite(f.values), f.values, np.nan)
    if f.metric.dim == 2:
        fig, ax = plt.subplots(figsize=(6, 5))
        cs = ax.contourf(axes[0], axes[1], vals.T, levels=30, cmap="viridis")
        ax.contour(axes[0], axes[1], vals.T, levels=15, colors="k", linewidths=0.3)
        fig.colorbar(cs, ax=ax, label=f"d(source, .) [{f.metric.name}]")
        for g in geodesics:
            ax.plot(g.points[:, 0], g.points[:, 1], "w-", lw=1.5)
            ax.plot(*g.points[-1, :2], "wo", ms=4)
        ax.plot(*f.source[:2], "r*", ms=10)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_aspect("equal")
    else:
        picks = np.linspace(0, f.grid.shape[2] - 1, 4).round().astype(int)
        fig, axs = plt.subplots(1, 4, figsize=(16, 4.2))
        for ax, k in zip(axs, picks):
            cs = ax.contourf(axes[0], axes[1], vals[:, :, k].T, levels=30, cmap="viridis")
            ax.set_title(f"{names[2]} = {axes[2][k]:.3g}")
            ax.set_xlabel(names[0])
            ax.set_ylabel(names[1])
            ax.set_aspect("equal")
            ax.plot(*f.source[:2], "r*", ms=8)
            for g in geodesics:
                ax.plot(g.points[:, 0], g.points[:, 1], "w-", lw=1)
            fig.colorbar(cs, ax=ax)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def field_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    source: Annotated[str, typer.Option(help='The source point, e.g. "0.1,-0.2".')],
    out: Annotated[Path, typer.Option(help="Directory for field.npy, error.npy, field.json "
                                           "and field.png.")],
    goal: Annotated[list[str] | None, typer.Option(
        help='A goal point (repeatable): its distance, error estimate and geodesic are '
             'printed and drawn.')] = None,
    resolution: Annotated[str | None, typer.Option(
        help='Cells along the longest side of the domain\'s bounding box (default: 100 in '
             '2-D, 40 in 3-D), or one number per coordinate, e.g. "40,40,24".')] = None,
    stencil: Annotated[str | None, typer.Option(
        help='Half widths of the stencil box in cells: "2", or one per coordinate, e.g. '
             '"3,3,2" (wider for strongly anisotropic metrics; default 2 in 2-D, 1 in '
             '3-D).')] = None,
    exact: Annotated[bool, typer.Option(
        help="Polish each goal's backtracked geodesic with the exact solver.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
) -> None:
    """Distance from --source to every point of the domain, with its error estimate."""
    m = metric_from_options(metric, metric_param, metric_module)
    if m.dim not in (2, 3):
        fail(f"distance fields are for metrics of dimension 2 or 3; {m.name!r} has "
             f"dimension {m.dim}")
    s = parse_point(source, m.dim, "--source")
    goals = [parse_point(g, m.dim, "--goal") for g in (goal or [])]
    res: Any = None
    if resolution is not None:
        try:
            cells = tuple(int(t) for t in resolution.split(","))
        except ValueError:
            fail(f'--resolution must be an integer or integers separated by commas, e.g. '
                 f'"100" or "40,40,24", got {resolution!r}')
        res = cells[0] if len(cells) == 1 else cells
    radius = None
    if stencil is not None:
        try:
            radius = tuple(int(t) for t in stencil.split(","))
        except ValueError:
            fail(f'--stencil must be integers separated by commas, e.g. "2" or "3,3,2", got '
                 f"{stencil!r}")
        if len(radius) == 1:
            radius = radius * m.dim
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        fail(f"cannot create --out {out}: {err.strerror or err}")
    import numpy as np

    import solvers

    try:
        try:
            f = solvers.distance_field(m, s, res, stencil=radius)
            rows, paths = [], []
            for g in goals:
                geo = f.geodesic(g, exact=exact)
                paths.append(geo)
                row = {"goal": g.tolist(), "distance": f(g), "error_estimate": f.error_at(g),
                       "backtracked_length": geo.length}
                if geo.exact is not None:
                    row["exact_length"] = geo.exact.length
                    row["exact_status"] = geo.exact.status.label
                rows.append(row)
        except InputError as err:
            fail(str(err))
        np.save(out / "field.npy", f.values)
        if f.error is not None:
            np.save(out / "error.npy", f.error)
        doc = f.to_dict()
        doc["goals"] = rows
        from finsler.status import json_ready

        (out / "field.json").write_text(json.dumps(json_ready(doc), indent=2) + "\n")
        _figure(f, paths, out / "field.png")
    except KeyboardInterrupt:
        interrupted("interrupted: the field was not finished; nothing more was written")
    rel = f.relative_error
    typer.echo(f"{m.name}: field on a {'x'.join(map(str, f.grid.shape))} grid, "
               f"{f.iterations} iterations, {f.cpu_time:.2f} s CPU, status {f.status.label}; "
               f"estimated relative error median {rel['median']:.2e}, p99 {rel['p99']:.2e}")
    for row in rows:
        line = (f"goal {row['goal']}: distance {row['distance']:.6g} "
                f"(+- {row['error_estimate']:.2g}), backtracked path "
                f"{row['backtracked_length']:.6g}")
        if "exact_length" in row:
            line += f", exact {row['exact_length']:.6g} ({row['exact_status']})"
        typer.echo(line)
    typer.echo(f"wrote {out / 'field.npy'}, {out / 'field.json'}, {out / 'field.png'}")


def register(app: typer.Typer) -> None:
    """Add ``field`` to the ``geodesics`` app."""
    app.command("field")(field_command)
