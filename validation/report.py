"""The learned-vs-exact benchmark report: ``report.md``, ``report.json`` and PNG figures.

``build_report(env, out, ...)`` loads a policy (a run directory, or the shipped policy of
the environment; ``quick=True`` trains a small Matsumoto policy in a few minutes if none is
shipped), runs :func:`validation.compare` on the evaluation pairs and writes

* ``report.json``: every number (the body of :meth:`Comparison.to_dict` plus the
  exact solver's own midpoint error floor);
* ``report.md``: the same numbers as tables, with the figures;
* ``learning_curve.png`` (Fig. 2 style, from the run's ``metrics.csv``);
* ``paths.png`` for 2-D metrics: 8 pairs learned vs exact vs straight, over a map of where
  ``F(x, .)`` is convex (the Finsler region) and the height contours (Matsumoto);
  ``carlike_headings.png`` for the car-like metric; ``panda_motion.png`` for the arm;
* ``length_ratio.png`` (histograms) and ``midpoint_error.png``.
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
from validation.comparison import Comparison, compare, midpoint_error, ratio_stats

__all__ = ["build_report", "load_report_policy", "read_learning_curve", "write_figures"]

LEARNED_COLOR = "tab:blue"
EXACT_COLOR = "black"
STRAIGHT_COLOR = "tab:orange"


# ----------------------------------------------------------------------------------------
# policy
# ----------------------------------------------------------------------------------------
def load_report_policy(
    env: str | None, run: str | Path | None, quick: bool, out: Path, progress: bool = True
) -> tuple[Any, Path | None, str]:
    """The policy to report on, its run directory (for the learning curve, may be None) and
    a sentence saying where it came from."""
    import learn

    if run is not None:
        run = Path(run)
        if not run.is_dir():
            raise InputError(f"run directory {run} does not exist")
        pol = learn.load_policy(run, env=env)
        return pol, run, f"run directory {run}"
    if env is None:
        raise InputError("give --env NAME or --run DIR")
    if env not in finsler.list_metrics():
        raise finsler.UnknownMetricError(
            f"unknown environment {env!r}; known: {', '.join(finsler.list_metrics())}")
    if env in learn.shipped_policies():
        pol = learn.load_policy(env)
        src = Path(pol.source)
        return pol, src if src.is_dir() else None, f"shipped policy for {env} ({src})"
    if quick:
        if env != "matsumoto":
            raise InputError(f"--quick trains a small policy only for matsumoto; {env!r} has "
                             "no shipped policy: train one with `geodesics train` and pass --run")
        run_dir = out / "quick_run"
        if (run_dir / "config.json").is_file():  # a previous --quick run: reuse its policy
            try:
                return learn.load_policy(run_dir), run_dir, (
                    f"small policy trained by an earlier --quick run, reused from {run_dir}")
            except InputError:
                pass  # incomplete or corrupt: train again below
        cfg = learn.default_config("matsumoto", timesteps=3_000_000, minutes=3.0,
                                   eval_every=5)
        learn.train(cfg, run_dir, progress=progress)
        return learn.load_policy(run_dir), run_dir, (
            f"small policy trained by --quick ({cfg.timesteps:.0e} timesteps or "
            f"{cfg.minutes:g} min) in {run_dir}")
    raise InputError(f"no shipped policy for {env!r} (shipped: "
                     f"{', '.join(learn.shipped_policies()) or 'none'}); pass --run DIR "
                     "or use --quick")


def read_learning_curve(run_dir: Path | None) -> list[dict[str, Any]]:
    """Rows of the run's metrics log (``metrics.csv``); empty if there is none."""
    if run_dir is None:
        return []
    from learn.storage import METRICS_FILE, read_metrics

    return read_metrics(Path(run_dir) / METRICS_FILE)


# ----------------------------------------------------------------------------------------
# figures
# ----------------------------------------------------------------------------------------
def _plt() -> Any:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _fig_learning_curve(rows: list[dict[str, Any]], cmp: Comparison, path: Path) -> bool:
    rows = [r for r in rows if "timesteps" in r and "success_rate" in r]
    if not rows:
        return False
    plt = _plt()
    ts = np.array([r["timesteps"] for r in rows], float)
    sr = 100 * np.array([r["success_rate"] for r in rows], float)
    wall = np.array([r.get("wall_seconds", np.nan) for r in rows], float)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, x, lab in ((axes[0], ts, "timesteps (evaluations of C)"),
                       (axes[1], wall / 60, "wall-clock time (minutes)")):
        ax.plot(x, sr, color=LEARNED_COLOR, label="learned policy (eval set)")
        ax.axhline(100 * cmp.exact.ceiling_rate, color=EXACT_COLOR, ls="--",
                   label="exact geodesics (ceiling)")
        ax.axhline(100 * cmp.straight.success_rate, color=STRAIGHT_COLOR, ls=":",
                   label="straight line (trivial baseline)")
        ax.set_xlabel(lab)
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(f"Learning curve, {cmp.metric} (D = {cmp.depth}, eps = {cmp.eps:g})")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return True


def _select_pairs(cmp: Comparison, k: int = 8) -> np.ndarray:
    """``k`` pairs spread over the learned/exact length ratio (worst included)."""
    r = cmp.ratios("learned")
    order = np.argsort(np.where(np.isfinite(r), r, -np.inf))
    if len(order) <= k:
        return order
    idx = np.unique(np.round(np.linspace(0, len(order) - 1, k)).astype(int))
    return order[idx]


def _finsler_background(ax: Any, metric: Metric, res: int = 160) -> None:
    lo, hi = metric.domain.bounds()
    lo, hi = lo[:2], hi[:2]
    xs = np.linspace(lo[0], hi[0], res)
    ys = np.linspace(lo[1], hi[1], res)
    gx, gy = np.meshgrid(xs, ys)
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    if metric.dim == 2:
        inside = metric.domain.contains(pts)
        lam = np.full(len(pts), np.nan)
        if metric.convex_everywhere:
            lam[inside] = 1.0
        else:
            lam[inside] = metric.convexity(pts[inside], n_directions=32)
        z = np.where(np.isnan(lam), np.nan, (lam > 0).astype(float)).reshape(gx.shape)
    else:  # car-like: (x, y) slice; convex everywhere (C^0-Finsler)
        inside = np.linalg.norm(pts, axis=1) <= float(hi[0])
        z = np.where(inside, 1.0, np.nan).reshape(gx.shape)
    from matplotlib.colors import ListedColormap

    ax.pcolormesh(gx, gy, z, cmap=ListedColormap(["#f4c7c3", "#e8f1e4"]), vmin=0, vmax=1,
                  shading="auto", rasterized=True)
    if metric.name == "matsumoto":
        h = -float(getattr(metric, "height", 1.0)) * (gx**2 + gy**2)
        h = np.where(np.isnan(z), np.nan, h)
        cs = ax.contour(gx, gy, h, levels=8, colors="grey", linewidths=0.6)
        ax.clabel(cs, fontsize=6, fmt="%.2f")
        circ = __import__("matplotlib.patches", fromlist=["Circle"]).Circle(
            (0, 0), metric.convex_radius, fill=False, ls="-.", color="darkgreen", lw=0.8)
        ax.add_patch(circ)


def _legend_handles() -> list[Any]:
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    return [
        Line2D([], [], color=LEARNED_COLOR, lw=1.5, marker=".", ms=3, label="learned"),
        Line2D([], [], color=EXACT_COLOR, lw=1.2, ls="--", label="exact (solvers)"),
        Line2D([], [], color=STRAIGHT_COLOR, lw=1.0, ls=":", label="straight line"),
        Patch(color="#e8f1e4", label="F(x,.) convex (Finsler)"),
        Patch(color="#f4c7c3", label="F(x,.) not convex"),
    ]


def _fig_paths_2d(cmp: Comparison, metric: Metric, path: Path) -> None:
    plt = _plt()
    sel = _select_pairs(cmp)
    ncol = 4
    nrow = math.ceil(len(sel) / ncol)
    fig, axes = plt.subplots(nrow, ncol, figsize=(3.5 * ncol, 3.9 * nrow + 0.8), squeeze=False)
    r = cmp.ratios("learned")
    for ax, i in zip(axes.ravel(), sel):
        _finsler_background(ax, metric, res=120)
        for ps, col, ls, lw in ((cmp.straight, STRAIGHT_COLOR, ":", 1.0),
                                (cmp.exact, EXACT_COLOR, "--", 1.2),
                                (cmp.learned, LEARNED_COLOR, "-", 1.5)):
            p = ps.paths[i]
            ax.plot(p[:, 0], p[:, 1], color=col, ls=ls, lw=lw,
                    marker="." if ps is cmp.learned else None, ms=3)
        s, g = cmp.pairs[i]
        ax.plot(*s[:2], "o", color="green", ms=5)
        ax.plot(*g[:2], "*", color="red", ms=8)
        ok = "success" if cmp.learned.success[i] else "fail"
        ax.set_title(f"pair {i}: learned/exact = {r[i]:.3f} ({ok})", fontsize=8)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("x (coordinate)", fontsize=8)
    for ax in axes[:, 0]:
        ax.set_ylabel("y (coordinate)", fontsize=8)
    for ax in axes.ravel()[len(sel):]:
        ax.axis("off")
    from matplotlib.lines import Line2D

    handles = [*_legend_handles(),
               Line2D([], [], ls="", marker="o", color="green", label="start"),
               Line2D([], [], ls="", marker="*", color="red", label="goal")]
    if metric.name == "matsumoto":
        handles.append(Line2D([], [], color="grey", lw=0.6, label="height h(p) contours"))
        handles.append(Line2D([], [], color="darkgreen", ls="-.", lw=0.8,
                              label=f"convex radius {metric.convex_radius:.4f}"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 5), fontsize=8)
    fig.suptitle(f"{metric.name}: learned vs exact paths ({2**cmp.depth} segments), "
                 "pairs spread over the length ratio", fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 0.97), h_pad=1.5)
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fig_carlike(cmp: Comparison, metric: Metric, path: Path) -> None:
    plt = _plt()
    sel = _select_pairs(cmp, 4)
    fig, axes = plt.subplots(2, len(sel), figsize=(3.6 * len(sel), 7), squeeze=False)
    r = cmp.ratios("learned")
    for k, i in enumerate(sel):
        ax = axes[0, k]
        _finsler_background(ax, metric, res=80)
        for ps, col, ls in ((cmp.exact, EXACT_COLOR, "--"), (cmp.learned, LEARNED_COLOR, "-")):
            p = ps.paths[i]
            ax.plot(p[:, 0], p[:, 1], color=col, ls=ls, lw=1.2)
            step = max(1, len(p) // 16)
            q = p[::step]
            ax.quiver(q[:, 0], q[:, 1], np.cos(q[:, 2]), np.sin(q[:, 2]), color=col,
                      angles="xy", scale=18, width=0.006, alpha=0.8)
        s0, g0 = cmp.pairs[i]
        ax.plot(s0[0], s0[1], "o", color="green", ms=5, label="start")
        ax.plot(g0[0], g0[1], "*", color="red", ms=8, label="goal")
        if k == 0:
            from matplotlib.lines import Line2D

            ax.legend(handles=[
                Line2D([], [], color=LEARNED_COLOR, label="learned (arrows: heading)"),
                Line2D([], [], color=EXACT_COLOR, ls="--", label="exact (arrows: heading)"),
                Line2D([], [], ls="", marker="o", color="green", label="start"),
                Line2D([], [], ls="", marker="*", color="red", label="goal"),
            ], fontsize=6, loc="lower left")
        ax.set_aspect("equal")
        ax.set_title(f"pair {i}: learned/exact = {r[i]:.3f}", fontsize=8)
        ax.set_xlabel("x (coordinate)", fontsize=7)
        ax.set_ylabel("y (coordinate)", fontsize=7)
        ax2 = axes[1, k]
        for ps, col, ls, lab in ((cmp.exact, EXACT_COLOR, "--", "exact"),
                                 (cmp.learned, LEARNED_COLOR, "-", "learned"),
                                 (cmp.straight, STRAIGHT_COLOR, ":", "straight")):
            ax2.plot(ps.paths[i][:, 2], color=col, ls=ls, label=lab)
        ax2.set_xlabel("path point index")
        ax2.set_ylabel("heading theta (rad)")
        ax2.grid(alpha=0.3)
        if k == 0:
            ax2.legend(fontsize=7)
    fig.suptitle("car-like: positions in the unit disk (shaded) with headings (arrows point "
                 "along theta), and theta along the path", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fig_panda(cmp: Comparison, metric: Metric, path: Path) -> None:
    plt = _plt()
    r = cmp.ratios("learned")
    i = int(_select_pairs(cmp, 3)[-1]) if len(cmp.pairs) > 1 else 0
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.8))
    ax = axes[0]
    colors = plt.cm.tab10(np.arange(7))
    for j in range(7):
        ax.plot(cmp.learned.paths[i][:, j], color=colors[j], lw=1.5, label=f"q{j + 1}")
        ax.plot(cmp.exact.paths[i][:, j], color=colors[j], lw=1.0, ls="--")
    ax.set_xlabel("path point index")
    ax.set_ylabel("joint angle (rad)")
    ax.set_title(f"pair {i}: joint angles (solid: learned, dashed: exact); "
                 f"length ratio {r[i]:.3f}", fontsize=9)
    ax.legend(fontsize=7, ncol=4)
    ax.grid(alpha=0.3)
    ax = axes[1]
    for ps, col, lab in ((cmp.learned, LEARNED_COLOR, "learned"), (cmp.exact, EXACT_COLOR,
                                                                    "exact")):
        fp = np.asarray(metric.frame_positions(ps.paths[i]))  # (n+1, 10, 3)
        idx = np.linspace(0, len(fp) - 1, 6).round().astype(int)
        for a, k in enumerate(idx):
            ax.plot(fp[k, :, 0], fp[k, :, 1], "-o", color=col, ms=2, lw=0.8,
                    alpha=0.25 + 0.75 * a / (len(idx) - 1), label=lab if a == len(idx) - 1
                    else None)
        ax.plot(fp[:, -1, 0], fp[:, -1, 1], color=col, lw=1.8, ls="-" if lab == "learned"
                else "--", label=f"hand trajectory ({lab})")
    px, py = float(metric.pole_x), float(metric.pole_y)
    ax.add_patch(__import__("matplotlib.patches", fromlist=["Circle"]).Circle(
        (px, py), 0.03, color="tab:red", label="pole"))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, world frame)")
    ax.set_ylabel("y (m, world frame)")
    ax.set_title("link positions seen from above (6 poses along the path, fading = earlier)",
                 fontsize=9)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fig_ratios(cmp: Comparison, path: Path) -> None:
    from matplotlib.ticker import MaxNLocator

    plt = _plt()
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for ax, ms, lab in ((axes[0], "length", "sum of C (eq. 4)"),
                        (axes[1], "length_quadrature", "quadrature length (eq. 58)")):
        a = cmp.ratios("learned", ms)
        b = cmp.ratios("straight", ms)
        a, b = a[np.isfinite(a)], b[np.isfinite(b)]
        hi = max(float(np.max(a, initial=1.0)), float(np.max(b, initial=1.0))) * 1.02
        lo = min(0.98, float(np.min(a, initial=1.0)), float(np.min(b, initial=1.0)))
        if hi / lo > 4:  # long tails (detours): logarithmic ratio axis
            bins = np.geomspace(lo, hi, 50)
            ax.set_xscale("log")
        else:
            bins = np.linspace(lo, hi, 40)
        ax.hist(b, bins=bins, alpha=0.55, color=STRAIGHT_COLOR, label="straight / exact")
        ax.hist(a, bins=bins, alpha=0.65, color=LEARNED_COLOR, label="learned / exact")
        ax.axvline(1.0, color="black", lw=0.8)
        ax.set_xlabel(f"length ratio, {lab} (1 = exact)")
        ax.set_ylabel("number of pairs")
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.legend(fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{cmp.metric}: path length relative to the exact discrete geodesic "
                 f"({len(cmp.pairs)} pairs)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def _fig_midpoint(cmp: Comparison, floor: Any, path: Path) -> None:
    plt = _plt()
    me = cmp.midpoint
    fig, ax = plt.subplots(figsize=(6.5, 4.2))
    ok = me.ok
    ax.scatter(me.d_sg[ok], 100 * me.err_max[ok], s=12, color=LEARNED_COLOR,
               label="learned pi(s, g)")
    if floor is not None:
        fo = floor.ok
        ax.scatter(floor.d_sg[fo], 100 * floor.err_max[fo], s=12, marker="x",
                   color=EXACT_COLOR, label="exact $p_{n/2}$ (discretisation floor)")
    ax.set_xlabel("exact discrete distance d(s, g)")
    ax.set_ylabel("midpoint error max(|d(s,m)-d/2|, |d(m,g)-d/2|) / d  (%)")
    ax.set_yscale("symlog", linthresh=0.1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(f"{cmp.metric}: first-level midpoint error ({me.segments} segments)",
                 fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def write_figures(cmp: Comparison, metric: Metric, out: Path, curve: list[dict[str, Any]],
                  floor: Any = None) -> list[str]:
    """Write the report's PNG figures into ``out``; returns their file names."""
    names = []
    if _fig_learning_curve(curve, cmp, out / "learning_curve.png"):
        names.append("learning_curve.png")
    if metric.dim == 2:
        _fig_paths_2d(cmp, metric, out / "paths.png")
        names.append("paths.png")
    if metric.name == "carlike":
        _fig_carlike(cmp, metric, out / "carlike_headings.png")
        names.append("carlike_headings.png")
    if metric.name == "panda-pole":
        _fig_panda(cmp, metric, out / "panda_motion.png")
        names.append("panda_motion.png")
    _fig_ratios(cmp, out / "length_ratio.png")
    names.append("length_ratio.png")
    if cmp.midpoint is not None:
        _fig_midpoint(cmp, floor, out / "midpoint_error.png")
        names.append("midpoint_error.png")
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


def _markdown(doc: dict[str, Any], figures: list[str], metric: Metric) -> str:
    sr = doc["success_rate"]
    lines = [
        f"# Learned vs exact geodesics: `{doc['metric']}`",
        "",
        f"- policy: {doc['policy_note']}",
        f"- pairs: {doc['pairs']} ({doc['pairs_note']})",
        f"- task: D = {doc['depth']} ({doc['segments']} segments), eps = {doc['eps']:g}; "
        "success iff every segment cost C(p_i, p_(i+1)) <= eps (section 5.1)",
        f"- metric: {metric.convexity_note}",
        "",
        "## Success rate",
        "",
        "| method | success |",
        "|---|---|",
        f"| learned policy | {_pct(sr['learned'])} |",
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
    for w in ("learned", "straight"):
        for ms, lab in (("length", "sum C (eq. 4)"), ("length_quadrature", "quadrature")):
            s = doc["length_ratio"][w][ms]
            lines.append(f"| {w} | {lab} | {_f(s['mean'])} | {_f(s['median'])} | "
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
        "| | seconds per path |",
        "|---|---|",
    ]
    t = doc["timing"]
    lines += [
        f"| learned, batch of {doc['pairs']} | {_f(t['learned_seconds_per_path_batched'], 3)} |",
        f"| learned, one pair at a time | {_f(t['learned_seconds_per_path_single'], 3)} |",
        f"| exact (globally seeded IPOPT + min-max) | {_f(t['exact_seconds_per_path'], 3)} |",
        "",
        f"Speed-up of the learned policy: {t['speedup_batched']:.3g}x (batched), "
        f"{t['speedup_single']:.3g}x (single pair).",
        "",
        f"Exact solver: {doc['exact_solver']['converged']}/{doc['pairs']} converged, status "
        f"counts {doc['exact_solver']['status_counts']}, on average "
        f"{doc['exact_solver']['mean_seeds_agreeing']:.1f} of "
        f"{doc['exact_solver']['mean_seeds_tried']:.1f} seeds reached the best energy.",
        "",
        "## Figures",
        "",
    ]
    captions = {
        "learning_curve.png": "Learning curve (success rate on the evaluation pairs) with "
        "the exact ceiling and the straight-line baseline.",
        "paths.png": "Learned (blue), exact (black dashed) and straight (orange dotted) paths "
        "for 8 pairs spread over the learned/exact length ratio; background: where F(x, .) "
        "is convex.",
        "carlike_headings.png": "Car-like paths with headings, and theta along the path.",
        "panda_motion.png": "Panda: joint angles along the path and link positions from "
        "above with the pole.",
        "length_ratio.png": "Histograms of the per-pair length ratio to the exact geodesic.",
        "midpoint_error.png": "First-level midpoint error against the pair's distance.",
    }
    if "learning_curve.png" not in figures:
        lines += ["No learning curve: the policy's directory holds no metrics log "
                  "(`metrics.csv`).", ""]
    for f in figures:
        lines += [f"![{f}]({f})", "", captions.get(f, ""), ""]
    lines += ["All numbers are also in `report.json`.", ""]
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
) -> dict[str, Any]:
    """Write the report for ``env`` (or the run's environment) into ``out``; returns the
    ``report.json`` document. ``policy`` overrides the loaded policy (any object with the
    policy interface, e.g. :class:`validation.StraightLine`). ``continuum`` (default: on
    unless ``quick``) adds continuum distances to the midpoint error, where
    :func:`solvers.distance` converges (the metric is Finsler along the path)."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    if policy is None:
        pol, run_dir, note = load_report_policy(env, run, quick, out, progress)
    else:
        pol, run_dir, note = policy, (Path(run) if run is not None else None), str(
            getattr(policy, "source", type(policy).__name__))
    metric = finsler.get_metric(pol.metric.name) if hasattr(pol, "metric") else \
        finsler.get_metric(env)
    if isinstance(pairs, (str, Path)):
        arr = load_pairs(pairs, metric)
        pairs_note = f"from {pairs}"
    elif pairs is not None:
        arr = np.asarray(pairs, dtype=np.float64)
        pairs_note = "given array"
    else:
        arr = finsler.default_pairs(metric)
        pairs_note = "the environment's default evaluation set, finsler.default_pairs"
    if continuum is None:
        continuum = not quick
    cmp = compare(pol, metric, arr, continuum=continuum, workers=workers, progress=progress)

    class _ExactMid:
        def midpoint(self, s: Any, g: Any) -> np.ndarray:
            return cmp.exact.paths[:, cmp.exact.paths.shape[1] // 2]

    floor = midpoint_error(_ExactMid(), metric, arr, segments=2**cmp.depth, exact=cmp.exact,
                           workers=workers, progress=progress)
    doc = cmp.to_dict()
    doc["policy_note"] = note
    doc["pairs_note"] = pairs_note
    doc["midpoint_error_exact_floor"] = floor.summary()
    doc["learning_curve"] = read_learning_curve(run_dir)
    doc["learned_length_ratio_per_pair"] = [
        None if not np.isfinite(x) else float(x) for x in cmp.ratios("learned")]
    figures = write_figures(cmp, metric, out, doc["learning_curve"], floor)
    doc["figures"] = figures
    doc["summary"] = {
        "learned_success": doc["success_rate"]["learned"],
        "exact_ceiling": doc["success_rate"]["exact_ceiling"],
        "straight_success": doc["success_rate"]["straight"],
        "learned_ratio": ratio_stats(cmp.ratios("learned")),
    }
    doc = _clean(doc)
    (out / "report.json").write_text(json.dumps(doc, indent=2, allow_nan=False))
    (out / "report.md").write_text(_markdown(doc, figures, metric))
    return doc


def _clean(o: Any) -> Any:
    """JSON-ready copy: numpy scalars/arrays to Python, non-finite floats to ``None``."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, (np.integer, int)):
        return int(o)
    if isinstance(o, (np.floating, float)):
        return float(o) if math.isfinite(float(o)) else None
    return o
