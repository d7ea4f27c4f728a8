"""``geodesics plot-curves``: Fig. 2 of the paper from a sweep directory (a thin layer over
`validation.curves` and `validation.figures.sweep_curves`)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Any

import typer

from finsler.errors import InputError
from validation.cli.common import fail, output_path

__all__ = ["FORMATS", "plot_curves", "plot_curves_command", "register"]

#: Figure formats accepted by --out (from its suffix).
FORMATS = (".png", ".pdf", ".svg")


def plot_curves(sweep_dir: str | Path, out: str | Path,
                column: str = "success_rate") -> tuple[Any, Path, Path]:
    """Read the sweep in ``sweep_dir``, draw `validation.figures.sweep_curves`
    (row 1: against all-inclusive evaluations of C, row 2: against wall time) into
    ``out`` and write the numbers to ``out`` with suffix ``.csv``. Everything is computed
    before anything is written, and each file is written atomically: bad input (InputError)
    leaves no file. Returns (figure, figure path, CSV path)."""
    from finsler.infra.files import atomic_write_bytes, atomic_write_text
    from validation import curves as cv
    from validation import figures as fg

    out = Path(out)
    if out.suffix.lower() not in FORMATS:
        raise InputError(f"--out {out}: the figure file must end in "
                         f"{', '.join(FORMATS)}")
    if out.is_dir():
        raise InputError(f"--out {out} is a directory; give a file name such as fig2.png")
    csv_path = out.with_suffix(".csv")
    sweep = cv.read_sweep(sweep_dir)
    by_kind = {kind: cv.learning_curves(sweep, x=kind, column=column) for kind in cv.X_KINDS}
    fig = fg.sweep_curves(by_kind, column=column)
    image = fg.figure_bytes(fig, out.suffix.lower().lstrip("."), dpi=120)
    text = cv.curves_csv([c for kind in cv.X_KINDS for c in by_kind[kind].values()])
    atomic_write_text(csv_path, text)
    atomic_write_bytes(out, image)
    return fig, out, csv_path


def plot_curves_command(
    sweep_dir: Annotated[Path, typer.Argument(
        metavar="DIR", help="Sweep directory: DIR/<env>/<variant>/seed-<s>/metrics.csv.")],
    out: Annotated[Path, typer.Option(
        parser=output_path,
        help="Figure file (.png, .pdf or .svg); the numbers go to the same name with "
             ".csv.")],
    column: Annotated[str, typer.Option(
        help="metrics.csv column to plot (success_rate, mean_length, "
             "mean_max_segment_cost, ...).")] = "success_rate",
) -> None:
    """Learning curves of a sweep (Fig. 2): one panel per environment; top row against
    evaluations of C (all-inclusive, the metrics' `timesteps`), bottom row against wall
    time in seconds; one line per variant = mean over seeds, band = +- standard error
    (std with ddof=1 / sqrt(n); none where one seed only).

    Each seed counts as a step function (its last evaluation at or before x) between its
    first and last evaluation; the CSV (columns env, variant, x_kind, x, mean, stderr,
    n_seeds) says how many seeds every point averages."""

    try:
        _, fig_path, csv_path = plot_curves(sweep_dir, out, column)
    except (InputError, OSError) as err:
        fail(str(err))
        return
    typer.echo(f"wrote {fig_path} and {csv_path}")


def register(app: typer.Typer) -> None:
    """Add ``plot-curves`` to the ``geodesics`` app."""
    app.command("plot-curves", short_help="Learning curves of a sweep (Fig. 2), one panel per "
                "environment, with a CSV of the plotted points.")(plot_curves_command)
