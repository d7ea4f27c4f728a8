"""``geodesics certify``: a certified interval ``lower <= d(start, goal) <= upper``
(`solvers.certify`, which picks the certificate by what the metric provides).

JSON keys of the 2-D certificate (``--json``): ``lower``, ``upper``, ``gap``
((upper - lower) / upper), then ``length``, ``length_error`` (the quadrature estimate of the path's
length; ``upper`` is the proven bound of it by interval arithmetic), ``upper_source`` (``path`` |
``zigzag``), ``path_upper``, ``path_gap`` (the solver's own path), ``triangles``, ``vertices``,
``unknowns``, ``directions``, ``lp_rows``, ``lp_rows_total``, ``lp_status``, ``lp_solver``,
``convexity`` (``convex`` | ``convexified``), ``convexity_note``, ``solver_status``,
``mesh`` (the settings), ``times`` (seconds: solve, mesh, bounds, lp, total), ``rounds``,
``stopped_by`` (target_gap | max_rounds | max_triangles | no_refinement | time_limit |
a failure's label), ``status`` ([`solvers.CertifyStatus`][solvers.CertifyStatus] label: certified |
budget_reached | time_limit | corrections_too_large | lp_failed), ``message``.

A conformal metric of dimension > 3 (hook ``conformal_factor_sx``, e.g. ``panda-pole``)
gets a proven lower bound instead, the best of the full run, the factor split into its parts
and the whole factor in 4 coordinates
(`solvers.certificates.conformal.split.certify_conformal_best`; JSON: ``lower``, ``upper``,
``ratio``, ``gap``, ``trivial``, ``potential_lower``, ``min_factor``, ``boxes``,
``enclosures``, ``cells``, ``momentum``, ``status``, ``bound_by`` (full | split | merged),
``split_lower``, ``constant``, ``shares``, ``part_dims``, ``full``, ``parts``, ``merged``
(the runs, each with the keys above), ...; ``--max-boxes`` is the work budget of all runs
together, ``--target-gap`` the gap that counts as certified).

Exit code 0 when the interval is certified or a budget ended the refinement (the interval
is proven either way; ``status`` says which), 1 when the refinement failed (the result,
with the best interval proven so far, is still printed and written).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

from finsler.errors import InputError
from finsler.infra.files import atomic_write_text, check_output_path
from validation.cli.common import (
    MetricModuleOption,
    MetricParamOption,
    fail,
    json_text,
    metric_from_options,
    parse_point,
)

if TYPE_CHECKING:
    from solvers import CertifyResult

__all__ = ["certify_command", "register"]


def certify_command(
    metric: Annotated[str, typer.Option(
        help="Registered metric: 2-D, a conformal one of any dimension, or 3-D and up with "
             "F(x, .) convex (see `geodesics metrics`).")],
    start: Annotated[str, typer.Option(help='Start point, e.g. "0.1,-0.2".')],
    goal: Annotated[str, typer.Option(help='Goal point, e.g. "0.5,0.3".')],
    mesh: Annotated[str, typer.Option(
        help="Mesh preset: coarse (a few 1e-2, fastest), default (gap <= 1e-2) or fine "
             "(gap <= 1e-3, minutes); in 3-D and up also p2 (a quadratic potential: gap <= "
             "1e-2 in minutes where F has affine rules; not for 2-D metrics).")] = "default",
    h: Annotated[float | None, typer.Option(
        "--h", help="Spacing of the first mesh along the path (overrides the preset).")] = None,
    directions: Annotated[int | None, typer.Option(
        help="Sampled directions per triangle (>= 8; overrides the preset).")] = None,
    target_gap: Annotated[float | None, typer.Option(
        help="Refine until the relative gap is at most this (overrides the preset).")] = None,
    time_limit: Annotated[float | None, typer.Option(
        help="Seconds after which no new refinement round starts (the result then depends "
             "on the machine's speed and says stopped_by: time_limit; without it the "
             "preset's work budgets, rounds and triangles, decide).")] = None,
    max_boxes: Annotated[int | None, typer.Option(
        help="n-D conformal metrics: work budget, boxes enclosed in all (default 2e6).")
    ] = None,
    out: Annotated[Path | None, typer.Option(help="Also write the JSON result here.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
) -> None:
    """Certified lower and upper bounds of the distance: a dual (potential) lower bound on a
    refined triangulation (second-order corrections bounded by interval arithmetic) and the
    solver's path length (proven upper bound)."""
    from solvers import CertifyStatus, certify, certify_settings

    m = metric_from_options(metric, metric_param, metric_module)
    s = parse_point(start, m.dim, "--start")
    g = parse_point(goal, m.dim, "--goal")
    try:
        m.domain.check(s, "--start")
        m.domain.check(g, "--goal")
        spec = certify_settings(m, mesh, h=h, directions=directions, target_gap=target_gap,
                                max_boxes=max_boxes, names=_FLAGS)
        if time_limit is not None and not (math.isfinite(time_limit) and time_limit > 0):
            raise InputError(f"--time-limit must be a positive number of seconds, got "
                             f"{time_limit!r}")
        if out is not None:
            check_output_path(out, "--out")
        res = certify(m, s, g, spec, time_limit=time_limit)
        doc = res.to_dict()
        if out is not None:
            atomic_write_text(out, json_text(doc), "certify result")
    except InputError as err:
        fail(str(err))
        return
    if as_json:
        typer.echo(json_text(doc))
    else:
        typer.echo(f"metric {m.name}: start {tuple(s.tolist())} goal {tuple(g.tolist())}")
        typer.echo(f"status = {res.status.label}   (stopped by {res.stopped_by})")
        _PRINT[type(res).__name__](res)
    if res.status in (CertifyStatus.LP_FAILED, CertifyStatus.CORRECTIONS_TOO_LARGE):
        fail(f"certify {res.status.label}: {res.message}", code=1)


#: The command line's names of `solvers.certify_settings`' overrides, for its messages.
_FLAGS = {"h": "--h", "directions": "--directions", "target_gap": "--target-gap",
          "max_boxes": "--max-boxes", "preset": "--mesh"}


def _print_conformal(res: Any) -> None:
    typer.echo(f"lower  = {res.lower:.10g}   ({res.method})")
    typer.echo(f"upper  = {res.upper:.10g}   (path length, proven by interval arithmetic)")
    typer.echo(f"ratio  = {res.ratio:.4f}   lower / upper; trivial bound "
               f"{res.trivial:.6g} (min f {res.min_factor:.6g} x |goal - start|)")
    runs = [f"full run {res.full.lower:.6g}"]
    if res.parts or res.constant:
        runs.append(f"split {res.split_lower:.6g} (constant {res.constant:g}"
                    + "".join(f", part in {d}-D {p.lower:.6g}"
                              for d, p in zip(res.part_dims, res.parts, strict=True))
                    + ")")
    if res.merged is not None:
        runs.append(f"whole factor in {res.merged.active_dims}-D {res.merged.lower:.6g}")
    typer.echo(f"bounds : {'; '.join(runs)}; the largest ({res.bound_by}) counts")
    typer.echo(f"work   : {res.enclosures} box enclosures, {res.boxes} boxes kept, "
               f"{res.cells} cells; {res.times['total']:.2f} s")


def _print_nd(res: Any) -> None:
    typer.echo(f"lower  = {res.lower:.10g}   (verified P1 potential on {res.cells} cells, "
               f"{res.relevant_cells} in the region; proven ratio {res.verified_ratio:.5f})")
    typer.echo(f"upper  = {res.upper:.10g}   (path length, proven by interval arithmetic)")
    typer.echo(f"gap    = {res.gap:.3e}   (upper - lower) / upper")
    typer.echo(f"time   : {res.times['total']:.2f} s (LP {res.times['lp']:.2f}, verify "
               f"{res.times['verify']:.2f})")


def _print_plane(res: CertifyResult) -> None:
    typer.echo(f"lower  = {res.lower:.10g}   (dual potential, P2 on {res.triangles} triangles, "
               f"{res.directions} directions)")
    typer.echo(f"upper  = {res.upper:.10g}   (path length, proven by interval arithmetic; "
               f"quadrature: {res.length:.10g} +- {res.length_error:.2g})")
    typer.echo(f"gap    = {res.gap:.3e}   (upper - lower) / upper")
    if res.upper_source == "zigzag":
        typer.echo(f"         upper from the solver's path with switchbacks; the path itself: "
                   f"{res.path_upper:.10g}, gap {res.path_gap:.3e}")
    typer.echo(f"mesh   : {res.vertices} vertices, {res.unknowns} unknowns, {len(res.rounds)} "
               f"LP round(s), last LP {res.lp_rows} rows ({res.lp_status}, {res.lp_solver})")
    typer.echo(f"time   : {res.times['total']:.2f} s (solve {res.times['solve']:.2f}, "
               f"bounds {res.times['bounds']:.2f}, LP {res.times['lp']:.2f})")
    typer.echo(f"convexity: {res.convexity}: {res.convexity_note}")


#: The printout of each certificate's result, by result type.
_PRINT = {"CertifyResult": _print_plane, "NDResult": _print_nd,
          "SplitCertifyResult": _print_conformal}


def register(app: typer.Typer) -> None:
    """Add ``certify`` to the ``geodesics`` app."""
    app.command("certify")(certify_command)
