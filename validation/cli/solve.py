"""``geodesics solve``: exact discrete geodesics for one pair or a file of pairs.

JSON schema (one pair with ``--json``, or ``--pairs``)::

    {"metric", "segments", "eps", "success_rate",
     "results": [{"points" (n+1, dim): the energy minimiser, "energy", "length",
                  "length_quadrature" (+- "length_quadrature_error"), "max_segment_cost",
                  "minmax_max_segment_cost",
                  "success" (min-max cost <= eps), "status", "segments", ...}]}

``length`` is always the sum of the costs C of the returned path. ``status`` is the
toolkit's name of the solver status (``success``, ``acceptable``, ``max_iterations``, ...:
`solvers.Status.label`), ``ipopt_status`` IPOPT's own return status.

With ``--tol`` each result also has ``length_estimate`` (the estimate of the continuum
length), ``error_estimate`` (absolute; ``null`` where no estimate exists, e.g. when the
solve could not refine), ``order`` (observed order of the polyline lengths),
``order_seen``, ``tol_reached`` and ``tol_levels``, and its ``segments`` is the size the
refinement stopped at. JSON never holds NaN or Infinity: such numbers are ``null``.

``success_rate`` is the fraction of pairs whose min-max refined discrete geodesic has every
segment cost ``<= eps``: the exact ceiling of the paper's task.

``--warm-start RUN_OR_ENV``: the policy's path of each pair is one more start of its batched
solve, beside the global seeds (the same batch, one more row at the final size), so the
result is never worse than without it; ``warm_start`` in the JSON names the policy.

``--solver auto|newton|ipopt`` picks the exact solver (the word "method" is kept for the
learning methods of ``--method-module``).
"""

from __future__ import annotations

import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Annotated, Any

import typer

import finsler
import solvers
from finsler.errors import InputError
from finsler.infra.pool import PoolInterrupted
from validation.cli.common import (
    MethodModuleOption,
    MetricModuleOption,
    MetricParamOption,
    fail,
    interrupted,
    json_text,
    metric_from_options,
    parse_point,
)

#: Printed (stderr) when --warm-start is used; the figures are those of the warm-start
#: results in benchmarks/results/warm-starts/ (``python benchmarks/warm_start.py`` writes them).
WARM_START_DEPRECATED = (
    "warning: --warm-start is deprecated: the default solve (without it) reaches the same "
    "optimum (125 of 126 fresh pairs measured) without loading torch and the policy (1.6-1.9 s "
    "of CPU); --warm-start still adds the learned path as one more start beside the global "
    "seeds, so its result is never worse")

if TYPE_CHECKING:  # numpy, solvers and learn are imported where used: --help stays light
    import numpy as np

__all__ = ["register", "solve_command", "solve_payload"]


def solve_payload(metric: Any, results: list[solvers.GeodesicResult], n: int) -> dict[str, Any]:
    """The JSON document of ``geodesics solve`` for solved pairs (with min-max refinement)."""
    import numpy as np

    eps = float(metric.task.eps)
    rows = []
    for r in results:
        row = r.to_dict()
        mm = r.minmax
        if mm is None:
            raise InputError("solve_payload needs results solved with minmax=True")
        row["minmax_max_segment_cost"] = mm.max_segment_cost
        row["success"] = bool(mm.max_segment_cost <= eps)
        rows.append(row)
    return {
        "metric": metric.name,
        "segments": n,
        "eps": eps,
        "success_rate": float(np.mean([row["success"] for row in rows])) if rows else 0.0,
        "results": rows,
    }


def _pairs_or_fail(path: Path, metric: finsler.Metric) -> np.ndarray:
    try:
        return finsler.load_pairs(path, metric, "--pairs")
    except InputError as err:
        fail(str(err))
        raise  # unreachable


def _warm_start(source: str | None, metric: finsler.Metric, pairs: np.ndarray,
                search: bool = False) -> tuple[np.ndarray | None, dict[str, Any] | None]:
    """Learned initial paths ``(K, 2**D + 1, dim)`` for ``--warm-start`` (None without it)
    and the payload's ``warm_start`` entry. solvers never imports learn: the joining is
    done here (`learn.warm_start_paths`)."""
    if source is None:
        return None, None
    import learn

    try:
        paths, pol = learn.warm_start_paths(source, metric, pairs, search=search)
    except InputError as err:  # name the option: the run's own message names a file in it
        if "--warm-start" in str(err):
            raise
        raise InputError(f"--warm-start {source!r}: {err}") from err
    return paths, {"policy": str(pol.source), "checkpoint": str(pol.checkpoint),
                   "segments": int(paths.shape[1] - 1), "route_search": bool(search),
                   "global_seeds": True}


def solve_command(
    metric: Annotated[str, typer.Option(help="Registered metric name (see `geodesics metrics`).")],
    start: Annotated[str | None, typer.Option(help='Start point, e.g. "0.1,-0.2".')] = None,
    goal: Annotated[str | None, typer.Option(help='Goal point, e.g. "0.5,0.3".')] = None,
    pairs: Annotated[
        Path | None, typer.Option(help="A .npy file of start/goal pairs, shape (K, 2, dim).")
    ] = None,
    segments: Annotated[
        int | None, typer.Option(help="Number of segments n (default 2**D of the task).")
    ] = None,
    out: Annotated[Path | None, typer.Option(
        help="Write the result to this file: FILE.csv (the path's points, a header of "
             "coordinate names; with --pairs the columns pair,point first), FILE.npy "
             "((n+1, dim), or (K, n+1, dim) with --pairs) or, for any other name, the "
             "JSON document.")] = None,
    plot: Annotated[Path | None, typer.Option(
        help="Draw the solved path (one pair) to this figure (.png, .pdf or .svg): 2-D "
             "over a map of the metric, 3-D its (x0, x1) projection and the coordinates "
             "against arc length, a robot arm its joint angles and the end effector's "
             "path.")] = None,
    as_json: Annotated[bool, typer.Option("--json", help="Print JSON.")] = False,
    workers: Annotated[int | None, typer.Option(
        help="Worker processes for --pairs (default: 1 for the batched Newton solver below "
             "1024 pairs, the batch being vectorised; else the CPU count).")] = None,
    solver: Annotated[str, typer.Option(
        help="auto (the batched Newton solver where it covers the metric, IPOPT "
             "otherwise), newton or ipopt.")] = "auto",
    device: Annotated[str | None, typer.Option(
        help="torch device of the Newton solver, e.g. cuda (default: numpy on the "
             "CPU).")] = None,
    progress: Annotated[bool, typer.Option(help="Show a progress bar for --pairs.")] = True,
    ray: Annotated[str | None, typer.Option(
        "--ray", metavar="ADDRESS",
        help="Solve --pairs as Ray tasks: HOST:6379 or auto (a running cluster), or local "
             "(a local Ray instance of --workers CPUs). Needs Ray: the project's "
             "'distributed' extra.")] = None,
    chunk_size: Annotated[int | None, typer.Option(
        help="Pairs per Ray task (default: about four tasks per CPU of the cluster, at most "
             "64 pairs).")] = None,
    warm_start: Annotated[str | None, typer.Option(
        "--warm-start", metavar="RUN_DIR_OR_ENV",
        help="Add a learned path as one more start of each pair, beside the global seeds "
             "(never a worse optimum than without it; costs loading the policy): a run "
             "directory of `geodesics train` or an environment with a shipped policy; the "
             "policy must be for --metric.")] = None,
    warm_search: Annotated[bool, typer.Option(
        "--warm-search", help="With --warm-start: seed with the route search's paths "
        "(learn.midpoint.search; values of C only) instead of the policy's plain paths.")] = False,
    tol: Annotated[float | None, typer.Option(
        help="Relative accuracy of the length: double the segments from --segments until "
             "the estimated error (Richardson extrapolation; says when the expected order "
             "is not seen) is below TOL * length, e.g. 1e-7.")] = None,
    metric_param: MetricParamOption = None,
    metric_module: MetricModuleOption = None,
    method_module: MethodModuleOption = None,
) -> None:
    """Exact discrete geodesics (globally seeded; the batched Newton solver, IPOPT where
    it does not cover the metric or cannot finish a pair) with min-max refinement.

    With --pairs and --out, finished pairs are kept in OUT.parts/ until the file is
    written, so running the same command again after an interruption resumes it (also
    across --workers and --ray)."""
    m = metric_from_options(metric, metric_param, metric_module)
    _check_options(pairs, start, goal, workers, ray, chunk_size, tol, warm_start,
                   warm_search)
    _check_files(out, plot, pairs, tol)
    arr = _read_pairs(m, pairs, start, goal)
    parts = None
    try:
        job, warm = _checked_job(m, arr, pairs, segments, workers, ray, chunk_size, tol,
                                 solver, device, warm_start, warm_search, method_module)
        if out is not None:
            out, parts = _checked_out(out, pairs is not None)
        if plot is not None:
            plot = finsler.check_output_path(plot, "--plot")
        results = _solve(job, progress and pairs is not None, parts)
    except InputError as err:
        fail(str(err))
    payload = solve_payload(m, results, job.segments)
    if warm is not None:
        payload["warm_start"] = warm
    text = json_text(payload, indent=None if pairs is not None else 2)
    if out is not None:
        _write(out, parts, _out_bytes(out, m, results, text, pairs is not None))
    if plot is not None:
        _plot(plot, m, results[0])
    if as_json:
        typer.echo(text)
    elif pairs is None:
        _print_pair(results[0], payload, tol)
        for path in (out, plot):
            if path is not None:
                typer.echo(f"written                   {path}")
    else:
        typer.echo(
            f"{len(results)} pairs, success rate (exact ceiling) {payload['success_rate']:.2%}"
            + (f", written to {out}" if out is not None else "")
        )


def _check_options(pairs: Path | None, start: str | None, goal: str | None,
                   workers: int | None, ray: str | None, chunk_size: int | None,
                   tol: float | None, warm_start: str | None, warm_search: bool) -> None:
    """Step 1: the options that go together."""
    import numpy as np

    if pairs is not None and (start is not None or goal is not None):
        fail("give either --start/--goal or --pairs, not both")
    if pairs is None and (start is None or goal is None):
        fail("give --start and --goal, or --pairs PAIRS.npy")
    if workers is not None and workers < 1:
        fail(f"--workers must be >= 1, got {workers}")
    if (ray is not None or chunk_size is not None) and pairs is None:
        fail("--ray and --chunk-size apply to --pairs")
    if chunk_size is not None and chunk_size < 1:
        fail(f"--chunk-size must be >= 1, got {chunk_size}")
    if tol is not None and not (np.isfinite(tol) and 0 < tol < 1):
        fail(f"--tol must be a relative tolerance in (0, 1), e.g. 1e-7, got {tol:g}")
    if warm_search and warm_start is None:
        fail("--warm-search applies to --warm-start")


def _check_files(out: Path | None, plot: Path | None, pairs: Path | None,
                 tol: float | None) -> None:
    """Step 1b: what --out's suffix and --plot can hold, before any solve."""
    from validation.export import FIGURE_FORMATS, check_suffix

    if plot is not None:
        if pairs is not None:
            fail("--plot draws one pair: give --start and --goal (with --pairs, --out "
                 "FILE.csv or FILE.npy exports every path)")
        try:
            check_suffix(plot, FIGURE_FORMATS, "--plot")
        except InputError as err:
            fail(str(err))
    if (out is not None and out.suffix.lower() == ".npy" and pairs is not None
            and tol is not None):
        fail("--out FILE.npy holds one array (K, n+1, dim), and with --tol each pair stops "
             "at its own number of segments: use --out FILE.csv or FILE.json")


def _out_bytes(out: Path, m: finsler.Metric, results: list[solvers.GeodesicResult],
               text: str, many: bool) -> bytes:
    """--out's content: the points as CSV or .npy (from the suffix; with --pairs in the
    several-pairs layout even for one), else the JSON."""
    from validation.export import path_bytes

    suffix = out.suffix.lower()
    if suffix not in (".csv", ".npy"):
        return text.encode()
    try:
        return path_bytes(results if many else results[0], suffix, m)
    except InputError as err:
        fail(f"--out {out}: {err}")
        raise  # unreachable


def _plot(plot: Path, m: finsler.Metric, result: solvers.GeodesicResult) -> None:
    """--plot: the solved path drawn, written atomically."""
    from validation.export import plot_geodesic

    try:
        plot_geodesic(m, result, plot)
    except InputError as err:
        fail(f"--plot {plot}: {err}")


def _read_pairs(m: finsler.Metric, pairs: Path | None, start: str | None,
                goal: str | None) -> np.ndarray:
    """Step 2: the pairs ``(K, 2, dim)``, from --pairs or parsed from --start / --goal."""
    import numpy as np

    if pairs is not None:
        return _pairs_or_fail(pairs, m)
    s = parse_point(start, m.dim, "--start")  # type: ignore[arg-type]
    g = parse_point(goal, m.dim, "--goal")  # type: ignore[arg-type]
    return np.stack([s, g])[None]


def _checked_job(m: finsler.Metric, arr: np.ndarray, pairs: Path | None,
                 segments: int | None, workers: int | None, ray: str | None,
                 chunk_size: int | None, tol: float | None, solver: str, device: str | None,
                 warm_start: str | None, warm_search: bool, method_module: list[str] | None
                 ) -> tuple[Any, dict[str, Any] | None]:
    """Step 3: the solver's own check of the input, once (naming the options), before
    --out and before a policy is loaded; the job it returns is solved without checking
    again. With --warm-start the learned paths join the job (and the payload's entry)."""
    from solvers import check_batch

    if method_module:
        import learn

        learn.import_method_modules(method_module)
    job = check_batch(m, arr, segments, minmax=True, workers=workers, ray_address=ray,
                      chunk_size=chunk_size, tol=tol, method=solver, device=device,
                      names=("--start", "--goal") if pairs is None else
                      ("--pairs starts", "--pairs goals"))
    inits, warm = _warm_start(warm_start, m, arr, warm_search)
    if inits is not None:
        typer.echo(WARM_START_DEPRECATED, err=True)
        job = job.with_initial_paths(inits)
    return job, warm


def _checked_out(out: Path, many: bool) -> tuple[Path, Path | None]:
    """Step 4: --out checked (its folder created) after every other input and before any
    solve: a bad --out must not cost a batch of solves, bad input must not leave folders.
    With --pairs, finished pairs are kept beside it (``OUT.parts``) until the JSON is
    written, so an interrupted run resumes where it stopped when run again."""
    out = finsler.check_output_path(out, "--out")
    parts = None
    if many:
        parts = out.with_name(out.name + ".parts")
        if parts.exists() and not parts.is_dir():
            raise finsler.OutputError(f"{parts} (the resumable parts of --out) "
                                      "exists and is not a folder")
    return out, parts


def _solve(job: Any, progress: bool, parts: Path | None) -> list[solvers.GeodesicResult]:
    """Step 5: the checked job solved; an interruption stops every worker and says what
    was kept (exit code 130)."""
    from solvers import run_batch

    try:
        return run_batch(job, progress=progress, checkpoint_dir=parts)
    except PoolInterrupted as stop:
        kept = (f"the pairs solved so far are kept in {parts}; run the same command to "
                "resume" if parts is not None else "nothing was kept (give --out to keep "
                "finished pairs)")
        interrupted(f"interrupted ({stop.signal_name}), all workers stopped: {kept}")


def _write(out: Path, parts: Path | None, data: bytes) -> None:
    """Step 6: --out written; the resumable parts removed once it is."""
    try:
        finsler.atomic_write_bytes(out, data, "--out")
    except InputError as err:
        kept = f"; the finished pairs are kept in {parts}" if parts is not None else ""
        fail(f"{err}{kept}")
    if parts is not None:
        shutil.rmtree(parts, ignore_errors=True)


def _print_pair(r: solvers.GeodesicResult, payload: dict[str, Any], tol: float | None
                ) -> None:
    """The text output of one pair."""
    import numpy as np

    row = payload["results"][0]
    typer.echo(f"status                    {r.status.label}")
    typer.echo(f"segments                  {r.segments}")
    typer.echo(f"length (sum C)            {r.length:.12g}")
    err = ("" if r.length_quadrature_error is None
           else f" +- {r.length_quadrature_error:.2g}")
    typer.echo(f"length (eq. 58 quadr.)    {r.length_quadrature:.12g}{err}")
    typer.echo(f"energy (sum C^2)          {r.energy:.12g}")
    typer.echo(f"max segment cost          {r.max_segment_cost:.6g}")
    typer.echo(f"min-max max segment cost  {row['minmax_max_segment_cost']:.6g}"
               f"  (eps {payload['eps']:g}: {'success' if row['success'] else 'fail'})")
    typer.echo(f"seeds agreeing / tried    {r.seeds_agreeing} / {r.seeds_tried}")
    typer.echo(f"solver, residual          {r.method}, {r.residual:.2e}")
    if r.error_estimate is not None:
        order = ("not seen" if not r.order_seen else f"{r.order:.2f}") + (
            f" (observed {r.order:.2f})" if r.order is not None and not r.order_seen
            else "")
        pm = (f"+- {r.error_estimate:.2e}" if np.isfinite(r.error_estimate)
              else "(no error estimate: the solve could not refine)")
        typer.echo(f"length (continuum est.)   {r.length_estimate:.15g} {pm} at "
                   f"{r.segments} segments, order {order}"
                   + ("" if r.tol_reached else f"  (tol {tol:g} NOT reached)"))
    nr = r.segments  # --tol may refine beyond --segments
    mid = (f"midpoint p_{nr // 2}          " if nr % 2 == 0 else
           f"p_{nr // 2} (n = {nr} is odd: no midpoint node) ")
    typer.echo(f"{mid:<26}{np.array2string(r.points[nr // 2], precision=8)}")
    typer.echo(f"wall time                 {r.wall_time:.3f} s")


def register(app: typer.Typer) -> None:
    """Add ``solve`` to the ``geodesics`` app."""
    app.command("solve")(solve_command)
