"""The learned-vs-exact benchmark report: ``report.md``, ``report.json`` and PNG figures.

``build_report(env, out, ...)`` loads a policy (a run directory, or the shipped policy of
the environment; ``quick=True`` trains a small Matsumoto policy in a few minutes if none is
shipped), runs `validation.compare` on the evaluation pairs and writes

* ``report.json``: every number (the body of `Comparison.to_dict` plus the
  exact solver's own midpoint error floor);
* ``report.md``: the same numbers as tables, with the figures;
* ``learning_curve.png`` (Fig. 2 style, from the run's ``metrics.csv``: success rate
  against all-inclusive evaluations of C and wall time);
* one path figure chosen by what the metric is (never by its name): ``paths.png`` for
  2-D metrics (8 pairs learned vs exact vs straight, over a map of where ``F(x, .)`` is
  convex, with height contours where the metric has a height map, e.g. Matsumoto);
  ``carlike_headings.png`` for planar poses (x, y, heading: car-like);
  ``panda_motion.png`` for metrics with the ``frame_positions`` kinematics hook (Panda);
  ``coordinates.png`` (every coordinate along the path) for any other metric;
* ``length_ratio.png`` (ratio - 1 on a log axis) and ``midpoint_error.png``.

The figures are drawn by `validation.figures`; files are written atomically.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np

import finsler
from finsler import Metric, load_pairs
from finsler.errors import InputError
from finsler.infra.files import made_folders
from validation.comparison import Comparison, compare, midpoint_error, ratio_stats
from validation.jsonout import jsonable
from validation.report_certify import certified_intervals, default_count, md_certified

__all__ = ["QUICK_TIMESTEPS", "build_report", "load_report_policy", "quick_training_note",
           "read_learning_curve", "write_figures"]

#: Work budget (evaluations of C) of the policy ``--quick`` trains for an environment
#: without a shipped policy: a budget, not a time limit, so that the policy does not depend
#: on the machine's load.
QUICK_TIMESTEPS = 3_000_000

# ----------------------------------------------------------------------------------------
# policy
# ----------------------------------------------------------------------------------------
def _quick_state(run_dir: Path) -> str:
    """``"none"`` (no --quick run yet), ``"unfinished"`` (interrupted: config.json without
    result.json) or ``"finished"``."""
    from learn.storage import RESULT_FILE

    if not (run_dir / "config.json").is_file():
        return "none"
    return "finished" if (run_dir / RESULT_FILE).is_file() else "unfinished"


def quick_training_note(env: str | None, run: str | Path | None, quick: bool,
                        out: str | Path) -> str | None:
    """The sentence to say before `build_report` trains a policy (``quick`` on an
    environment without a shipped policy and without a finished ``--quick`` run in
    ``out``): what it trains, its budget, the expected time and how to stop it; None when
    nothing will be trained."""
    if run is not None or env is None or not quick:
        return None
    import learn

    if env in learn.shipped_policies():
        return None
    run_dir = Path(out) / "quick_run"
    state = _quick_state(run_dir)
    if state == "finished":
        return None
    what = ("resuming the interrupted --quick training" if state == "unfinished" else
            f"no shipped policy for {env!r}: training one first")
    return (f"{what} ({QUICK_TIMESTEPS:.0e} evaluations of C, typically 2-5 minutes on one "
            f"CPU core for a 2-D metric; the bar shows the rate and time left) into "
            f"{run_dir}; Ctrl-C keeps it resumable, and the same command resumes it")


def load_report_policy(
    env: str | None, run: str | Path | None, quick: bool, out: Path, progress: bool = True,
    checkpoint: str = "best", metric_params: dict[str, Any] | None = None,
) -> tuple[Any, Path | None, str]:
    """The policy to report on (``checkpoint``: ``best``, selected on the validation set,
    or ``latest``), its run directory (for the learning curve, may be None) and a sentence
    saying where it came from and which checkpoint file was used. ``metric_params``, if
    given, must be the parameters the policy was trained with."""
    import learn

    if checkpoint not in ("best", "latest"):
        raise InputError(f"checkpoint must be best or latest, got {checkpoint!r}")
    if run is not None:
        run = Path(run)
        if not run.is_dir():
            raise InputError(f"run directory {run} does not exist")
        pol = learn.load_any_policy(run, checkpoint=checkpoint, env=env,
                                    metric_params=metric_params)
        return pol, run, f"run directory {run}, {pol.checkpoint}"
    if env is None:
        raise InputError("give --env NAME or --run DIR")
    finsler.registry.check_name(env, "environment")
    if env in learn.shipped_policies():
        pol = learn.load_policy(env, checkpoint=checkpoint, metric_params=metric_params)
        src = Path(pol.source)
        chosen_on = ("the default evaluation set (optimistic there)"
                     if selected_on_default_set(pol) else "the validation set")
        return pol, src if src.is_dir() else None, (
            f"shipped policy for {env} ({src}, {pol.checkpoint}; its checkpoint was selected "
            f"on {chosen_on}; see learn/policies/README.md for fresh pairs)")
    if quick:
        run_dir = out / "quick_run"
        state = _quick_state(run_dir)
        if state == "finished":  # a previous --quick run: reuse its policy
            try:  # (env: a quick run of another environment is not reused)
                pol = learn.load_policy(run_dir, checkpoint=checkpoint, env=env,
                                        metric_params=metric_params)
                return pol, run_dir, (
                    f"small policy trained by an earlier --quick run, reused from {run_dir}"
                    f", {pol.checkpoint}")
            except InputError:
                if _quick_run_env(run_dir) not in (None, env):
                    raise InputError(
                        f"{run_dir} holds a --quick run for {_quick_run_env(run_dir)!r}, not "
                        f"{env!r}: choose another --out") from None
                # incomplete or corrupt: train again below
        # a work budget only: a wall-clock limit would make the policy depend on the load
        # (any environment: its default configuration at a small budget; a policy for a
        # hard task trained this way is weak, and the report says how it was trained)
        cfg = learn.default_config(env, timesteps=QUICK_TIMESTEPS, eval_every=5,
                                   metric_params=metric_params)
        if state == "unfinished" and _quick_run_env(run_dir) not in (None, env):
            raise InputError(f"{run_dir} holds a --quick run for {_quick_run_env(run_dir)!r}, "
                             f"not {env!r}: choose another --out")
        # an interrupted --quick run is resumed (TrainingInterrupted propagates: the caller
        # says what was kept), never reported half-trained
        learn.train_run(cfg, run_dir, resume=state == "unfinished", progress=progress)
        pol = learn.load_policy(run_dir, checkpoint=checkpoint)
        return pol, run_dir, (
            f"small policy trained by --quick ({cfg.timesteps:.0e} evaluations of C) in "
            f"{run_dir}, {pol.checkpoint}")
    raise InputError(f"no shipped policy for {env!r} (shipped: "
                     f"{', '.join(learn.shipped_policies()) or 'none'}); pass --run DIR "
                     "or use --quick")


def _quick_run_env(run_dir: Path) -> str | None:
    """The environment of an earlier --quick run's config.json (None if unreadable)."""
    try:
        env = json.loads((run_dir / "config.json").read_text()).get("env")
    except (OSError, ValueError, AttributeError):
        return None
    return env if isinstance(env, str) else None


def time_to_success(rows: list[dict[str, Any]],
                    thresholds: tuple[float, ...] = (0.9, 0.95, 0.99)) -> dict[str, Any]:
    """For each threshold, the first evaluations of C (all-inclusive) and wall seconds at
    which a running mean of 5 consecutive validation evaluations reached it (None if
    never): one lucky evaluation does not count."""
    from validation.curves import running_mean_threshold

    out: dict[str, Any] = {}
    for t in thresholds:
        hit = running_mean_threshold(rows, t, window=5) if rows else None
        out[f"{t:g}"] = None if hit is None else {
            "timesteps": float(hit.timesteps), "wall_seconds": float(hit.wall_seconds)}
    return out


def read_learning_curve(run_dir: Path | None) -> list[dict[str, Any]]:
    """Rows of the run's metrics log (``metrics.csv``); empty if there is none."""
    if run_dir is None:
        return []
    from learn.storage import METRICS_FILE, read_metrics

    return read_metrics(Path(run_dir) / METRICS_FILE)


def curve_set(run_dir: Path | None) -> str:
    """Which pairs the run's learning curve was evaluated on, from its ``config.json``
    (``selection``): ``"validation"`` (runs since the validation set existed) or
    ``"default"`` (the shipped policies, trained before it: their curve and best checkpoint
    are on the default evaluation set)."""
    if run_dir is None:
        return "validation"
    from learn.storage import read_json

    try:
        selection = str(read_json(Path(run_dir) / "config.json").get("selection", ""))
    except Exception:  # no or unreadable config: the loader has already judged the run
        return "validation"
    return "default" if "DEFAULT evaluation set" in selection else "validation"


def selected_on_default_set(policy: Any) -> bool:
    """Whether ``policy``'s best checkpoint was chosen on the default evaluation set (the
    shipped policies trained before the validation set existed), so that its figures
    there are optimistic."""
    return curve_set(Path(policy.source)) == "default"


CURVE_SETS = {"validation": "the validation pairs (finsler.validation_pairs)",
              "default": "the DEFAULT evaluation pairs (finsler.default_pairs: this run "
                         "predates the validation set, so its curve and its best checkpoint "
                         "are on the set reported here, which is optimistic)"}


# ----------------------------------------------------------------------------------------
# figures (drawn by validation.figures)
# ----------------------------------------------------------------------------------------
def write_figures(cmp: Comparison, metric: Metric, out: Path, curve: list[dict[str, Any]],
                  floor: Any = None, curve_pairs: str = "validation") -> list[str]:
    """Write the report's PNG figures (drawn by `validation.figures`) into ``out``,
    atomically; returns their file names."""
    from validation import figures as fg

    drawn = [("learning_curve.png", fg.learning_curve(curve, cmp, curve_pairs))]
    # by what the metric is, not by its name: its dimension, its coordinates, its hooks
    if metric.dim == 2:
        drawn.append(("paths.png", fg.paths_2d(cmp, metric)))
    elif fg.is_planar_pose(metric):
        drawn.append(("carlike_headings.png", fg.carlike_headings(cmp, metric)))
    elif fg.has_kinematics(metric):
        drawn.append(("panda_motion.png", fg.panda_motion(cmp, metric)))
    else:
        drawn.append(("coordinates.png", fg.coordinates_along_path(cmp, metric)))
    drawn.append(("length_ratio.png", fg.length_ratios(cmp)))
    if cmp.midpoint is not None:
        drawn.append(("midpoint_error.png", fg.midpoint_errors(cmp, floor)))
    names = []
    for name, fig in drawn:
        if fig is not None:
            fg.save_figure(fig, out / name, dpi=120)
            names.append(name)
    return names


# ----------------------------------------------------------------------------------------
# markdown
# ----------------------------------------------------------------------------------------
def _f(x: Any, digits: int = 4) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.{digits}g}"


def _pct(x: float) -> str:
    return f"{100 * x:.0f}%"


def _params(metric: Metric) -> dict[str, Any]:
    """The metric's parameters (its [`finsler.MetricSpec`][finsler.MetricSpec]'s)."""
    return dict(finsler.MetricSpec.of(metric).params)


def _params_text(metric: Metric) -> str:
    return ", ".join(f"{k} = {v}" for k, v in _params(metric).items()) or "(none)"


_LABELS = {"searched": "learned + route search"}


def _md_summary(doc: dict[str, Any], metric: Metric) -> list[str]:
    """The title, the run's facts, the success rates and the length ratios."""
    sr = doc["success_rate"]
    lines: list[str] = [
        f"# Learned vs exact geodesics: `{doc['metric']}`",
        "",
        f"- policy: {doc['policy_note']}",
        f"- pairs: {doc['pairs']} ({doc['pairs_note']})",
        f"- task: D = {doc['depth']} ({doc['segments']} segments), eps = {doc['eps']:g}; "
        "success iff every segment cost C(p_i, p_(i+1)) <= eps (section 5.1)",
        f"- metric: {metric.convexity_note}",
        f"- metric parameters: {_params_text(metric)}",
        "",
        "## Success rate",
        "",
        "| method | success |",
        "|---|---|",
        f"| learned policy | {_pct(sr['learned'])} |",
        *([f"| learned policy + route search | {_pct(sr['searched'])} |"]
          if "searched" in sr else []),
        f"| exact geodesics, min-max refined (ceiling) | {_pct(sr['exact_ceiling'])} |",
        f"| exact geodesics, energy minimiser as solved | {_pct(sr['exact_energy_path'])} |",
        f"| straight line cut into {doc['segments']} pieces (trivial baseline) | "
        f"{_pct(sr['straight'])} |",
        "",
        "The success rate alone flatters a method (the straight line already scores above); "
        "the path quality below says how far the paths are from geodesics.",
        "",
        "## Length ratio to the exact discrete geodesic (per pair)",
        "",
        "| method | measure | mean | median | 95th pct | max | min | pairs |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for w in doc["length_ratio"]:
        for ms, lab in (("length", "sum C (eq. 4)"), ("length_quadrature", "quadrature")):
            s = doc["length_ratio"][w][ms]
            lines.append(f"| {_LABELS.get(w, w)} | {lab} | {_f(s['mean'])} | {_f(s['median'])} | "
                         f"{_f(s['p95'])} | {_f(s['max'])} | {_f(s['min'])} | {s['count']} |")
    lines += [
        "",
        "Both lengths are compared measure for measure: learned sum C over exact sum C, "
        "learned quadrature length over exact quadrature length. The exact path minimises "
        "the discrete energy sum C^2 at this resolution, so a ratio slightly below 1 (by "
        "O(1/n)) is a discretisation effect; far below 1 happens only where F(x, .) is not "
        "convex, where the discrete sum of C rewards zig-zags that no continuum curve "
        "realises (Proposition 1 fails there).",
        "",
    ]
    return lines


def _md_search(doc: dict[str, Any]) -> list[str]:
    """What the route search did (if it ran)."""
    lines: list[str] = []
    if "search" in doc:
        sc = doc["search"]
        lines += [
            "`learned + route search` (`searched` in `report.json`) is the same policy with "
            "the route search (`learn.midpoint.search`): at the "
            f"top {sc['levels']} levels, {sc['candidates_per_level']} candidate midpoints "
            "per sub-pair (the policy's, the coordinate midpoint and offsets around both) "
            "are each completed by the policy's own halves and the cheapest completed path "
            f"(sum C) is kept, then {sc['polish']} polishing sweeps by the policy's "
            f"midpoints of neighbours, {sc.get('windows', 0)} sweeps re-generating windows "
            "of the path by the policy's own trees where that is shorter, and "
            f"{sc.get('equalize', 0)} rounds moving the points along the path towards "
            "equal segment costs. It evaluates C "
            f"{sc['evaluations_of_C_per_path']:.0f} times per path (values only: no "
            "derivative of C, like the paper's method); before the equalizing rounds it is "
            "never longer than the policy's own path, and no step raises the largest "
            "segment cost above eps or the policy's own, so it never fails where the "
            "policy succeeds.",
            "",
        ]
    return lines


def _md_midpoint(doc: dict[str, Any], metric: Metric) -> list[str]:
    """The first-level midpoint errors (if measured), with continuum distances if computed."""
    lines: list[str] = []
    me = doc.get("midpoint_error")
    if me is not None:
        fl = doc.get("midpoint_error_exact_floor")
        lines += [
            "## Midpoint error of the first-level prediction m = pi(s, g)",
            "",
            f"|d(s, m) - d(s, g)/2| / d(s, g) and |d(m, g) - d(s, g)/2| / d(s, g), with d the "
            f"exact discrete geodesic length ({me['segments']} segments for (s, g), "
            f"{me['segments'] // 2} for each half).",
            "",
            "| midpoint | error | mean | median | 95th pct | max | pairs |",
            "|---|---|---|---|---|---|---|",
        ]
        rows = [("learned", me)] + ([("exact p_(n/2) (floor)", fl)] if fl else [])
        for lab, src in rows:
            for key in ("err_start", "err_goal"):
                s = src[key]
                lines.append(f"| {lab} | {key} | {_f(s['mean'])} | {_f(s['median'])} | "
                             f"{_f(s['p95'])} | {_f(s['max'])} | {s['count']} |")
        if "continuum" in me:
            c = me["continuum"]
            s = c["err_max"]
            lines += [
                "",
                f"With continuum distances (`solvers.distance`, only where it converged: the "
                f"metric is Finsler along the path): {c['pairs_used']} pairs, max error mean "
                f"{_f(s['mean'])}, median {_f(s['median'])}, max {_f(s['max'])}. Status "
                f"counts: {c['status_counts']}.",
            ]
        else:
            lines += ["", "Continuum distances were not computed (`--quick`; run without it "
                      "or with `--continuum` to add them where the metric is Finsler)."]
            if not metric.convex_everywhere:
                lines[-1] += (" This metric is not Finsler on most of its domain: there the "
                              "continuum distance is that of the convexified metric and "
                              "discrete lengths depend on the resolution.")
        lines.append("")
    return lines


def _md_finsler_and_timing(doc: dict[str, Any]) -> list[str]:
    """The share of non-convex path points, the time per path and the exact solver's statuses."""
    lines: list[str] = []
    nc = doc["nonconvex_point_fraction"]
    lines += [
        "## Where the metric is Finsler",
        "",
        f"Share of path points where F(x, .) is not convex: learned {_pct(nc['learned'])}, "
        f"exact {_pct(nc['exact'])}, straight {_pct(nc['straight'])}. The path figures "
        "shade the non-convex region.",
        "",
        "## Time per path",
        "",
        *_md_timing(doc),
        "",
        f"Exact solver: {doc['exact_solver']['converged']}/{doc['pairs']} converged, status "
        f"counts {doc['exact_solver']['status_counts']}, on average "
        f"{doc['exact_solver']['mean_seeds_agreeing']:.1f} of "
        f"{doc['exact_solver']['mean_seeds_tried']:.1f} seeds reached the best energy.",
        "",
        "## Figures",
        "",
    ]
    return lines


def _md_timing(doc: dict[str, Any]) -> list[str]:
    """The time-per-path table: learned at each timed batch size beside the exact solve
    (one pair at a time for batch 1, else the report's batched solve), and the speed-ups."""
    t = doc["timing"]
    k = t.get("exact_batch", doc["pairs"])
    one = t.get("exact_seconds_per_path_single")
    lines = [
        f"Learned times: warm (one call first), the median of {t.get('repeats', 1)} calls "
        f"(21 single-pair calls for batch 1), torch limited to {t.get('threads', '?')} "
        "thread(s); the pairs are repeated up to the batch size. Exact times: "
        + (f"batch 1 is `solvers.solve_geodesic` on one pair at a time (median of a few "
           f"pairs); the others are the share per path of this report's batched solve of "
           f"{k} pairs (globally seeded, min-max refined)." if one is not None else
           f"the share per path of this report's batched solve of {k} pairs."),
        "",
        "| batch | learned, s per path | exact, s per path | speed-up |",
        "|---|---|---|---|",
    ]
    exact_batched = t["exact_seconds_per_path"]
    for b, sec in (t.get("learned_seconds_per_path") or {}).items():
        ex = one if (b == "1" and one is not None) else exact_batched
        where = "" if (b == "1" and one is not None) else f" (batch of {k})"
        lines.append(f"| {int(b):,} | {_f(sec, 3)} | {_f(ex, 3)}{where} | "
                     f"{ex / sec:.3g}x |" if sec else f"| {b} | - | - | - |")
    if "searched_seconds_per_path_batched" in t:
        lines.append(f"| {doc['pairs']:,}, learned + route search | "
                     f"{_f(t['searched_seconds_per_path_batched'], 3)} | "
                     f"{_f(exact_batched, 3)} | {t['speedup_searched']:.3g}x |")
    lines += ["", f"Speed-up of the learned policy on {doc['metric']}: "
              f"{t['speedup_batched']:.3g}x at batch {t.get('learned_batch', k):,}"
              + (f", {t['speedup_single']:.3g}x one pair at a time"
                 if t.get("speedup_single") else "") + "."]
    return lines


def _md_figures(doc: dict[str, Any], figures: list[str]) -> list[str]:
    """The figures with their captions (and the time to a success rate)."""
    lines: list[str] = []
    captions = {
        "learning_curve.png": "Learning curve (success rate on "
        + CURVE_SETS[doc.get("learning_curve_pairs", "validation")] + ", from "
        "`metrics.csv`) against evaluations of C, all-inclusive (column `timesteps`: every "
        "evaluation the learner made in training), and wall time, both on log axes, with the "
        "exact ceiling "
        "and the straight-line baseline; when the log also has the paper's count "
        "(`timesteps_paper`, section 5.2) and it differs, a third panel uses it.",
        "paths.png": "Learned (blue), exact (black dashed) and straight (orange dotted) paths "
        "for 8 pairs spread over the learned/exact length ratio; background: where F(x, .) "
        "is convex.",
        "carlike_headings.png": "Planar positions with headings, and theta along the path.",
        "panda_motion.png": "Joint angles along the path and link positions from above "
        "(with the pole, for the Panda metric).",
        "coordinates.png": "Every coordinate along the path for 4 pairs spread over the "
        "length ratio (learned solid, exact dashed, straight dotted).",
        "length_ratio.png": "How much longer than the exact geodesic each path is: the "
        "per-pair ratio - 1 (sum of C) on a log axis, so that 0.1 % and 1 % look different; "
        "histogram of the learned paths, and the cumulative share with the straight line.",
        "midpoint_error.png": "First-level midpoint error against the pair's distance.",
    }
    if "learning_curve.png" not in figures:
        lines += ["No learning curve: the policy's directory holds no metrics log "
                  "(`metrics.csv`).", ""]
    else:
        reached = []
        for t, hit in doc.get("time_to_success", {}).items():
            reached.append(f"{100 * float(t):.0f}%: " + (
                "not reached" if hit is None else
                f"{hit['timesteps']:.3g} evaluations of C, {hit['wall_seconds']:.0f} s"))
        on = ("validation" if doc.get("learning_curve_pairs", "validation") == "validation"
              else "default-set")
        lines += ["Time to a success rate (the first evaluation at which a running mean of "
                  f"5 consecutive {on} evaluations reached it): "
                  + "; ".join(reached) + ".", ""]
    for f in figures:
        lines += [f"![{f}]({f})", "", captions.get(f, ""), ""]
    return lines


def _markdown(doc: dict[str, Any], figures: list[str], metric: Metric) -> str:
    """``report.md``: one section per step, in the order a reader meets them."""
    lines = [*_md_summary(doc, metric), *_md_search(doc), *_md_midpoint(doc, metric),
             *md_certified(doc), *_md_finsler_and_timing(doc), *_md_figures(doc, figures),
             "All numbers are also in `report.json`.", ""]
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------
# entry point
# ----------------------------------------------------------------------------------------

def build_report(
    env: str | None,
    out: str | Path,
    *,
    run: str | Path | None = None,
    pairs: str | Path | np.ndarray | None = None,
    quick: bool = False,
    continuum: bool | None = None,
    workers: int | None = None,
    progress: bool = True,
    policy: Any = None,
    checkpoint: str = "best",
    metric_params: dict[str, Any] | None = None,
    search: Any = True,
    certify: int | None = None,
) -> dict[str, Any]:
    """Write the report for ``env`` (or the run's environment) into ``out``; returns the
    ``report.json`` document. ``policy`` overrides the loaded policy (any object with the
    policy interface, e.g. `validation.StraightLine`). ``continuum`` (default: on
    unless ``quick``) adds continuum distances to the midpoint error, where
    [`solvers.distance`][solvers.distance] converges (the metric is Finsler along the path).
    ``checkpoint``: ``best`` (selected on the validation set) or ``latest``.
    ``metric_params``: the metric's parameters; a loaded policy must have been trained
    with them (its run's own parameters are always the ones reported). ``search``: also
    report the policy-guided route search (`learn.Policy.search`; True = the default
    `learn.SearchSpec`, or a spec, or False/None for none), for policies that have
    it. ``certify``: certified intervals for this many pairs, in any dimension
    `solvers.certify` accepts (`validation.report_certify`; default:
    `default_count` pairs with the preset
    `preset_for` picks; 0: none)."""
    if certify is not None and (isinstance(certify, bool) or not isinstance(certify, int)
                                or certify < 0):
        raise InputError(f"certify must be a number of pairs >= 0, got {certify!r}")
    with made_folders(out) as folder:  # a failed report leaves no new empty folders
        return _build_report(env, folder, run=run, pairs=pairs, quick=quick,
                             continuum=continuum, workers=workers, progress=progress,
                             policy=policy, checkpoint=checkpoint, metric_params=metric_params,
                             search=search, certify=certify)


def _build_report(env: str | None, out: Path, *, run: str | Path | None,
                  pairs: str | Path | np.ndarray | None, quick: bool, continuum: bool | None,
                  workers: int | None, progress: bool, policy: Any,
                  checkpoint: str, metric_params: dict[str, Any] | None,
                  search: Any = True, certify: int | None = None) -> dict[str, Any]:
    out.mkdir(parents=True, exist_ok=True)
    if policy is None:
        pol, run_dir, note = load_report_policy(env, run, quick, out, progress, checkpoint,
                                                metric_params)
    else:
        pol, run_dir, note = policy, (Path(run) if run is not None else None), str(
            getattr(policy, "source", type(policy).__name__))
    if hasattr(pol, "metric"):  # the policy's own metric, with its parameters
        metric = pol.metric
    else:
        if env is None:
            raise InputError("give env for a policy without a metric attribute")
        metric = finsler.MetricSpec.resolve(env, metric_params).build()
    if isinstance(pairs, (str, Path)):
        arr = load_pairs(pairs, metric, "--pairs")
        pairs_note = f"from {pairs}"
    elif pairs is not None:
        arr = np.asarray(pairs, dtype=np.float64)
        pairs_note = "given array"
    else:
        arr = finsler.default_pairs(metric)
        pairs_note = "the environment's default evaluation set, finsler.default_pairs"
    if continuum is None:
        continuum = not quick
    spec = None
    if search is True and callable(getattr(pol, "search", None)):
        from learn import SearchSpec

        spec = SearchSpec()
    elif search not in (None, False, True):
        spec = search
    cmp = compare(pol, metric, arr, continuum=continuum, workers=workers, progress=progress,
                  search=spec, timing_repeats=3 if quick else 5,
                  exact_single=1 if quick else 3)

    class _ExactMid:
        def midpoint(self, s: Any, g: Any) -> np.ndarray:
            return cmp.exact.paths[:, cmp.exact.paths.shape[1] // 2]

    floor = midpoint_error(_ExactMid(), metric, arr, segments=2**cmp.depth, exact=cmp.exact,
                           workers=workers, progress=progress)
    doc = cmp.to_dict()
    doc["policy_note"] = note
    doc["metric_params"] = _params(metric)
    doc["pairs_note"] = pairs_note
    doc["midpoint_error_exact_floor"] = floor.summary()
    doc["learning_curve"] = read_learning_curve(run_dir)
    doc["learning_curve_pairs"] = curve_set(run_dir)
    doc["time_to_success"] = time_to_success(doc["learning_curve"])
    doc["learned_length_ratio_per_pair"] = [
        None if not np.isfinite(x) else float(x) for x in cmp.ratios("learned")]
    n_cert = default_count(metric, quick) if certify is None else int(certify)
    cert = certified_intervals(cmp, metric, n_cert, quick)
    if cert is not None:
        doc["certified"] = cert
    figures = write_figures(cmp, metric, out, doc["learning_curve"], floor,
                            doc["learning_curve_pairs"])
    doc["figures"] = figures
    doc["summary"] = {
        "learned_success": doc["success_rate"]["learned"],
        "exact_ceiling": doc["success_rate"]["exact_ceiling"],
        "straight_success": doc["success_rate"]["straight"],
        "learned_ratio": ratio_stats(cmp.ratios("learned")),
    }
    if cmp.searched is not None:
        doc["summary"]["searched_success"] = doc["success_rate"]["searched"]
        doc["summary"]["searched_ratio"] = ratio_stats(cmp.ratios("searched"))
    doc = jsonable(doc)
    from finsler.infra.files import atomic_write_text

    atomic_write_text(out / "report.json", json.dumps(doc, indent=2, allow_nan=False))
    atomic_write_text(out / "report.md", _markdown(doc, figures, metric))
    return doc
