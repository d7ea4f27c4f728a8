"""Every matplotlib figure of the project, in one module.

Each drawing function returns a `matplotlib.figure.Figure` built with the
object-oriented API on an Agg canvas: no pyplot, no backend switch, no global state, at
import or later (figures are garbage-collected, nothing to close). `save_figure`
writes one atomically (rendered in memory, then ``finsler.infra.files.atomic_write_bytes``).

Report figures (`validation.report`): `learning_curve`, `paths_2d`,
`carlike_headings`, `panda_motion`, `length_ratios`,
`midpoint_errors`. Sweep figure (Fig. 2 of the paper, ``geodesics plot-curves``):
`sweep_curves`. One solved path (``geodesics solve --plot``): `geodesic_path`.
"""

from __future__ import annotations

import io
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import matplotlib
import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.colors import ListedColormap
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Circle, Patch
from matplotlib.ticker import MaxNLocator

if TYPE_CHECKING:
    from finsler import Metric
    from validation.comparison import Comparison, MidpointErrors
    from validation.curves import Curve

__all__ = [
    "EXACT_COLOR",
    "LEARNED_COLOR",
    "OLD_LOG_X_LABEL",
    "PAPER_X_LABEL",
    "STRAIGHT_COLOR",
    "X_LABELS",
    "carlike_headings",
    "coordinates_along_path",
    "figure_bytes",
    "geodesic_path",
    "has_kinematics",
    "height_map",
    "is_planar_pose",
    "learning_curve",
    "length_ratios",
    "midpoint_errors",
    "new_figure",
    "panda_motion",
    "paths_2d",
    "save_figure",
    "sweep_curves",
]

LEARNED_COLOR = "tab:blue"
EXACT_COLOR = "black"
SEARCHED_COLOR = "#2ca02c"
STRAIGHT_COLOR = "tab:orange"
#: Axis labels of the two x axes of a learning curve (metrics.csv columns).
X_LABELS = {
    "timesteps": "evaluations of C (all-inclusive, count)",
    "wall_seconds": "wall-clock time (s)",
}
PAPER_X_LABEL = "timesteps, paper's count (section 5.2)"
#: x label of a log without ``timesteps_paper``: written before the run-directory contract
#: made ``timesteps`` all-inclusive, so the count is not claimed to be.
OLD_LOG_X_LABEL = "timesteps (older log: count not known to be all-inclusive)"


# ----------------------------------------------------------------------------------------
# plumbing
# ----------------------------------------------------------------------------------------
def new_figure(figsize: tuple[float, float]) -> Figure:
    """A figure on its own Agg canvas (no pyplot)."""
    fig = Figure(figsize=figsize)
    FigureCanvasAgg(fig)
    return fig


def figure_bytes(fig: Figure, fmt: str = "png", dpi: int = 120) -> bytes:
    """The figure rendered in memory (``fmt``: png, pdf, svg)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=fmt, dpi=dpi)
    return buf.getvalue()


def save_figure(fig: Figure, path: Path, dpi: int = 120) -> None:
    """Write ``fig`` to ``path`` atomically (format from the suffix, default png)."""
    from finsler.infra.files import atomic_write_bytes

    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    atomic_write_bytes(path, figure_bytes(fig, fmt, dpi))


# ----------------------------------------------------------------------------------------
# report: learning curve of one run
# ----------------------------------------------------------------------------------------
def learning_curve(rows: Sequence[Mapping[str, Any]], cmp: Comparison,
                   pairs: str = "validation") -> Figure | None:
    """Success rate of one run against all-inclusive evaluations of C (metrics.csv
    ``timesteps``) and wall time, with the exact ceiling and the straight-line baseline;
    a third panel against ``timesteps_paper`` if the log has it and it differs from
    ``timesteps``. A log without ``timesteps_paper`` predates the run-directory contract:
    its ``timesteps`` axis is labelled as such, not as all-inclusive. ``pairs``: the pair
    set the rows were evaluated on (``validation`` or ``default``, see
    `validation.report.curve_set`), named in the legend. None if the rows hold no
    (timesteps, success_rate)."""
    rows = [r for r in rows if "timesteps" in r and "success_rate" in r]
    if not rows:
        return None
    ts = np.array([r["timesteps"] for r in rows], float)
    sr = 100 * np.array([r["success_rate"] for r in rows], float)
    wall = np.array([r.get("wall_seconds", np.nan) for r in rows], float)
    contract = all("timesteps_paper" in r for r in rows)
    panels: list[tuple[np.ndarray, str]] = [
        (ts, X_LABELS["timesteps"] if contract else OLD_LOG_X_LABEL),
        (wall / 60, "wall-clock time (minutes)")]
    if contract:
        tp = np.array([r["timesteps_paper"] for r in rows], float)
        if not np.array_equal(tp, ts):
            panels.append((tp, PAPER_X_LABEL))
    fig = new_figure((5.5 * len(panels), 4))
    axes = fig.subplots(1, len(panels))
    for ax, (x, lab) in zip(axes, panels):
        keep = x > 0 if np.any(x > 0) else np.ones(len(x), bool)  # log axis: no zero
        ax.plot(x[keep], sr[keep], color=LEARNED_COLOR, marker=".", ms=3,
                label=f"learned policy ({pairs} set)")
        ax.axhline(100 * cmp.exact.ceiling_rate, color=EXACT_COLOR, ls="--",
                   label="exact geodesics (ceiling)")
        ax.axhline(100 * cmp.straight.success_rate, color=STRAIGHT_COLOR, ls=":",
                   label="straight line (trivial baseline)")
        if np.any(x > 0):  # the rise is early: logarithmic evaluations (or minutes)
            ax.set_xscale("log")
            lab = f"{lab}, log axis"
        ax.set_xlabel(lab)
        if lab.startswith(PAPER_X_LABEL):
            ax.set_title("paper's count: not every evaluation of C", fontsize=9)
        ax.set_ylabel("success rate (%)")
        ax.set_ylim(-2, 102)
        ax.grid(alpha=0.3)
    axes[0].legend(loc="lower right", fontsize=8)
    fig.suptitle(f"Learning curve, {cmp.metric} (D = {cmp.depth}, eps = {cmp.eps:g})")
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------------------
# report: paths
# ----------------------------------------------------------------------------------------
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
    if metric.dim > 2:  # the (x0, x1) slice through the centre of the other coordinates
        lo_all, hi_all = metric.domain.bounds()
        rest = np.broadcast_to(0.5 * (lo_all[2:] + hi_all[2:]), (len(pts), metric.dim - 2))
        full = np.concatenate([pts, rest], axis=1)
    else:
        full = pts
    inside = metric.domain.contains(full)
    lam = np.full(len(pts), np.nan)
    if metric.convex_everywhere:
        lam[inside] = 1.0
    else:
        lam[inside] = metric.convexity(full[inside], n_directions=32)
    z = np.where(np.isnan(lam), np.nan, (lam > 0).astype(float)).reshape(gx.shape)
    ax.pcolormesh(gx, gy, z, cmap=ListedColormap(["#f4c7c3", "#e8f1e4"]), vmin=0, vmax=1,
                  shading="auto", rasterized=True)
    height = height_map(metric)
    if height is not None and metric.dim == 2:
        h = np.where(np.isnan(z.ravel()), np.nan, height(pts)).reshape(gx.shape)
        cs = ax.contour(gx, gy, h, levels=8, colors="grey", linewidths=0.6)
        ax.clabel(cs, fontsize=6, fmt="%.2f")
    radius = metric.convex_radius
    if radius is not None and metric.dim == 2:
        ax.add_patch(Circle((0, 0), radius, fill=False, ls="-.", color="darkgreen", lw=0.8))


def height_map(metric: Metric) -> Any:
    """The height function ``(N, 2) -> (N,)`` drawn as contours under 2-D paths: the
    metric's ``height_map`` hook (`finsler.hooks`; Matsumoto's slope of eq. 21
    provides it) if it provides one, else None."""
    return metric.height_map if metric.provides("height_map") else None


def is_planar_pose(metric: Metric) -> bool:
    """True for a 3-D metric whose coordinates are a planar position and a heading angle
    (third coordinate named theta, heading or yaw), like the car-like metric."""
    names = tuple(metric.domain.names)
    return metric.dim == 3 and len(names) == 3 and names[2] in ("theta", "heading", "yaw")


def has_kinematics(metric: Metric) -> bool:
    """True for a metric that provides the ``frame_positions(q) -> (N, frames, 3)`` hook
    (`finsler.hooks`: a robot arm's forward kinematics, like the Panda metric)."""
    return metric.provides("frame_positions")


def _legend_handles() -> list[Any]:
    return [
        Line2D([], [], color=LEARNED_COLOR, lw=1.5, marker=".", ms=3, label="learned"),
        Line2D([], [], color=EXACT_COLOR, lw=1.2, ls="--", label="exact (solvers)"),
        Line2D([], [], color=STRAIGHT_COLOR, lw=1.0, ls=":", label="straight line"),
        Patch(color="#e8f1e4", label="F(x,.) convex (Finsler)"),
        Patch(color="#f4c7c3", label="F(x,.) not convex"),
    ]


def paths_2d(cmp: Comparison, metric: Metric) -> Figure:
    """Learned, exact and straight paths of 8 pairs spread over the length ratio, over a
    map of where ``F(x, .)`` is convex (2-D metrics; height contours for Matsumoto)."""
    sel = _select_pairs(cmp)
    ncol = 4
    nrow = math.ceil(len(sel) / ncol)
    fig = new_figure((3.5 * ncol, 3.9 * nrow + 0.8))
    axes = fig.subplots(nrow, ncol, squeeze=False)
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
    handles = [*_legend_handles(),
               Line2D([], [], ls="", marker="o", color="green", label="start"),
               Line2D([], [], ls="", marker="*", color="red", label="goal")]
    if height_map(metric) is not None:
        handles.append(Line2D([], [], color="grey", lw=0.6, label="height h(p) contours"))
    radius = metric.convex_radius
    if radius is not None:
        handles.append(Line2D([], [], color="darkgreen", ls="-.", lw=0.8,
                              label=f"convex radius {radius:.4f}"))
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 5), fontsize=8)
    fig.suptitle(f"{metric.name}: learned vs exact paths ({2**cmp.depth} segments), "
                 "pairs spread over the length ratio", fontsize=10)
    fig.tight_layout(rect=(0, 0.07, 1, 0.97), h_pad=1.5)
    return fig


def carlike_headings(cmp: Comparison, metric: Metric) -> Figure:
    """Planar pose metrics (`is_planar_pose`, e.g. car-like): positions with heading
    arrows (top row) and the heading along the path."""
    sel = _select_pairs(cmp, 4)
    fig = new_figure((3.6 * len(sel), 7))
    axes = fig.subplots(2, len(sel), squeeze=False)
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
    fig.suptitle(f"{metric.name}: positions in the domain (shaded) with headings (arrows "
                 "point along theta), and theta along the path", fontsize=10)
    fig.tight_layout()
    return fig


def panda_motion(cmp: Comparison, metric: Metric) -> Figure:
    """Arms (`has_kinematics`, e.g. Panda): joint angles along one path, and link
    positions seen from above (with the metric's ``landmarks``, e.g. Panda's pole)."""
    r = cmp.ratios("learned")
    i = int(_select_pairs(cmp, 3)[-1]) if len(cmp.pairs) > 1 else 0
    fig = new_figure((12, 4.8))
    axes = fig.subplots(1, 2)
    ax = axes[0]
    colors = matplotlib.colormaps["tab10"](np.arange(metric.dim) % 10)
    names = _coordinate_names(metric)
    for j in range(metric.dim):
        ax.plot(cmp.learned.paths[i][:, j], color=colors[j], lw=1.5, label=names[j])
        ax.plot(cmp.exact.paths[i][:, j], color=colors[j], lw=1.0, ls="--")
    ax.set_xlabel("path point index")
    ax.set_ylabel("joint angle (rad)")
    ax.set_title(f"pair {i}: joint angles (solid: learned, dashed: exact); "
                 f"length ratio {r[i]:.3f}", fontsize=9)
    ax.legend(fontsize=7, ncol=4)
    ax.grid(alpha=0.3)
    ax = axes[1]
    for ps, col, lab in ((cmp.learned, LEARNED_COLOR, "learned"),
                         (cmp.exact, EXACT_COLOR, "exact")):
        fp = np.asarray(metric.frame_positions(ps.paths[i]))  # (n+1, 10, 3)
        idx = np.linspace(0, len(fp) - 1, 6).round().astype(int)
        for a, k in enumerate(idx):
            ax.plot(fp[k, :, 0], fp[k, :, 1], "-o", color=col, ms=2, lw=0.8,
                    alpha=0.25 + 0.75 * a / (len(idx) - 1),
                    label=lab if a == len(idx) - 1 else None)
        ax.plot(fp[:, -1, 0], fp[:, -1, 1], color=col, lw=1.8,
                ls="-" if lab == "learned" else "--", label=f"hand trajectory ({lab})")
    for label, where in metric.landmarks().items():
        ax.add_patch(Circle((float(where[0]), float(where[1])), 0.03, color="tab:red",
                            label=label))
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, world frame)")
    ax.set_ylabel("y (m, world frame)")
    ax.set_title("link positions seen from above (6 poses along the path, fading = earlier)",
                 fontsize=9)
    ax.legend(fontsize=7, loc="best")
    ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _coordinate_names(metric: Metric) -> list[str]:
    names = list(metric.domain.names)
    return names if len(names) == metric.dim else [f"x{j}" for j in range(metric.dim)]


def coordinates_along_path(cmp: Comparison, metric: Metric) -> Figure:
    """Any metric: every coordinate along the path (learned solid, exact dashed, straight
    dotted) for 4 pairs spread over the length ratio; one panel per pair."""
    sel = _select_pairs(cmp, 4)
    r = cmp.ratios("learned")
    fig = new_figure((4.2 * len(sel), 4.2))
    axes = fig.subplots(1, len(sel), squeeze=False)[0]
    colors = matplotlib.colormaps["tab10"](np.arange(metric.dim) % 10)
    names = _coordinate_names(metric)
    for ax, i in zip(axes, sel):
        for j in range(metric.dim):
            ax.plot(cmp.learned.paths[i][:, j], color=colors[j], lw=1.5, label=names[j])
            ax.plot(cmp.exact.paths[i][:, j], color=colors[j], lw=1.0, ls="--")
            ax.plot(cmp.straight.paths[i][:, j], color=colors[j], lw=0.7, ls=":")
        ax.set_title(f"pair {i}: learned/exact = {r[i]:.3f}", fontsize=8)
        ax.set_xlabel("path point index")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("coordinate value")
    axes[0].legend(fontsize=7, ncol=2, title="solid learned, dashed exact, dotted straight",
                   title_fontsize=6)
    fig.suptitle(f"{metric.name}: coordinates along the path", fontsize=10)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------------------
# report: path quality
# ----------------------------------------------------------------------------------------
#: Smallest excess ``ratio - 1`` drawn on the log axis of `length_ratios`: a path at most
#: this much longer than the exact one (or shorter: the exact path is the discrete energy
#: minimiser, not the shortest polyline) is drawn at this floor and counted in the legend.
EXCESS_FLOOR = 1e-6


def _excess(r: np.ndarray) -> tuple[np.ndarray, int]:
    """``ratio - 1`` of the finite ratios, floored at `EXCESS_FLOOR`, and how many were."""
    r = r[np.isfinite(r)] - 1.0
    low = int(np.sum(r <= EXCESS_FLOOR))
    return np.maximum(r, EXCESS_FLOOR), low


def length_ratios(cmp: Comparison) -> Figure:
    """How much longer than the exact discrete geodesic each pair's path is (sum of C):
    ``ratio - 1`` on a logarithmic axis, so that 0.1 % and 1 % look different. Left: the
    histogram of the learned paths (and with the route search, if the comparison has it);
    right: the cumulative share of pairs, with the straight line beside them (its excess is
    usually orders of magnitude larger, so it gets the wider axis of its own panel)."""
    fig = new_figure((11.5, 4.2))
    ax, ax2 = fig.subplots(1, 2)
    sets = [("learned", LEARNED_COLOR, "learned")]
    if cmp.searched is not None:
        sets.append(("searched", SEARCHED_COLOR, "learned + route search"))
    data = {w: _excess(cmp.ratios(w)) for w, _, _ in sets}
    data["straight"] = _excess(cmp.ratios("straight"))
    learned_all = np.concatenate([data[w][0] for w, _, _ in sets])
    if learned_all.size:
        lo = max(EXCESS_FLOOR, float(learned_all.min()) / 1.5)
        hi = max(float(learned_all.max()) * 1.5, lo * 10)
        bins = np.geomspace(lo, hi, 40)
        for w, col, lab in sets:
            x, low = data[w]
            med = float(np.median(x)) if x.size else float("nan")
            note = f", {low} at <= {EXCESS_FLOOR:g}" if low else ""
            ax.hist(x, bins=bins, alpha=0.6 if w == "learned" else 1.0, color=col,
                    histtype="stepfilled" if w == "learned" else "step", lw=1.6,
                    label=f"{lab} (median {100 * med:.3g} %{note})")
            ax.axvline(med, color=col, ls="--", lw=1.0)
        ax.set_xscale("log")
    ax.set_xlabel("ratio - 1 = (length / exact length) - 1   (sum of C; log axis)")
    ax.set_ylabel("number of pairs")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.set_title("learned paths: excess length over the exact geodesic", fontsize=9)
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3, which="both")
    for w, col, lab in [*sets, ("straight", STRAIGHT_COLOR, "straight line")]:
        x, _ = data[w]
        if x.size:
            xs = np.sort(x)
            ax2.step(xs, 100 * np.arange(1, len(xs) + 1) / len(xs), where="post", color=col,
                     lw=1.6, label=f"{lab} (median {100 * float(np.median(xs)):.3g} %)")
    ax2.set_xscale("log")
    ax2.set_xlabel("ratio - 1 (sum of C; log axis)")
    ax2.set_ylabel("pairs with at most this excess (%)")
    ax2.set_ylim(0, 102)
    ax2.set_title("cumulative, with the straight line", fontsize=9)
    ax2.legend(fontsize=7, loc="lower right")
    ax2.grid(alpha=0.3, which="both")
    fig.suptitle(f"{cmp.metric}: path length relative to the exact discrete geodesic "
                 f"({len(cmp.pairs)} pairs; quadrature lengths in report.json)", fontsize=10)
    fig.tight_layout()
    return fig


def midpoint_errors(cmp: Comparison, floor: MidpointErrors | None = None) -> Figure:
    """First-level midpoint error of the learned policy against the pair's distance, with
    the exact path's own midpoint (discretisation floor) if given."""
    me = cmp.midpoint
    fig = new_figure((6.5, 4.2))
    ax = fig.subplots()
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
    return fig


# ----------------------------------------------------------------------------------------
# sweeps: Fig. 2 (mean +- standard error over seeds)
# ----------------------------------------------------------------------------------------
def _column_label(column: str) -> str:
    if column == "success_rate":
        return "success rate (fraction of validation pairs)"
    if column == "mean_length":
        return "mean path length (validation pairs, sum of C)"
    if column == "mean_max_segment_cost":
        return "mean max segment cost C (validation pairs)"
    return column


def sweep_curves(curves: Mapping[str, Mapping[tuple[str, str], Curve]],
                 column: str = "success_rate") -> Figure:
    """Fig. 2: one column of panels per environment, one row per x axis (``curves`` maps
    an x kind, ``"timesteps"`` and/or ``"wall_seconds"``, to the output of
    `validation.curves.learning_curves`). One line per variant (step function of the
    seed mean, exact on the default grid of `learning_curves`; a dot
    marks its last value), shaded band = mean +- standard error (absent where one seed
    only); colours
    are fixed per variant across panels. Axes: ``fig.axes`` is row-major,
    ``len(curves) * n_envs`` panels."""
    kinds = list(curves)
    keys = sorted({k for c in curves.values() for k in c})
    envs = sorted({e for e, _ in keys})
    variants = sorted({v for _, v in keys})
    cmap = matplotlib.colormaps["tab10"]
    color = {v: cmap(i % 10) for i, v in enumerate(variants)}
    fig = new_figure((max(6.5, 5.0 * len(envs) + 0.5), 3.8 * len(kinds) + 0.8))
    axes = fig.subplots(len(kinds), len(envs), squeeze=False)
    for row, kind in enumerate(kinds):
        for col, env in enumerate(envs):
            ax = axes[row, col]
            for var in variants:
                c = curves[kind].get((env, var))
                if c is None:
                    continue
                nmax = int(c.n_seeds.max())
                ax.plot(c.x, c.mean, drawstyle="steps-post", color=color[var], lw=1.4,
                        marker="o", ms=3, markevery=[len(c.x) - 1],  # the last value
                        label=f"{var} ({nmax} seed{'s' if nmax != 1 else ''})")
                ax.fill_between(c.x, c.mean - c.stderr, c.mean + c.stderr, step="post",
                                color=color[var], alpha=0.22, lw=0)
            ax.set_xlabel(X_LABELS.get(kind, kind))
            ax.set_ylabel(_column_label(column))
            if column == "success_rate":
                ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
            ax.set_title(env, fontsize=10)
            ax.legend(fontsize=7, loc="best")
    fig.suptitle(f"{_column_label(column)}\nmean over seeds, band = +- standard error",
                 fontsize=10)
    fig.tight_layout()
    return fig


# ----------------------------------------------------------------------------------------
# one solved path (``geodesics solve --plot``, `validation.plot_geodesic`)
# ----------------------------------------------------------------------------------------
def _unit_speed_map(ax: Any, metric: Metric, res: int = 140) -> Any:
    """``mean_u F(x, u)`` over 16 unit directions, on the (x0, x1) slice through the centre
    of the other coordinates; outside the domain blank. Returns the colour mesh."""
    lo, hi = metric.domain.bounds()
    gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], res), np.linspace(lo[1], hi[1], res))
    pts = np.stack([gx.ravel(), gy.ravel()], 1)
    rest = np.broadcast_to(0.5 * (lo[2:] + hi[2:]), (len(pts), metric.dim - 2))
    full = np.concatenate([pts, rest], axis=1)
    inside = metric.domain.contains(full)
    ang = np.linspace(0, 2 * np.pi, 16, endpoint=False)
    val = np.full(len(pts), np.nan)
    x = full[inside]
    speeds = []
    for a in ang:
        u = np.zeros_like(x)
        u[:, 0], u[:, 1] = np.cos(a), np.sin(a)
        speeds.append(np.asarray(metric.F(x, u), dtype=float))
    val[inside] = np.mean(speeds, axis=0)
    spread = np.nanmax(val) - np.nanmin(val) if inside.any() else 0.0
    if not spread > 1e-9 * np.nanmax(np.abs(val), initial=1.0):  # F independent of x here
        ax.pcolormesh(gx, gy, np.where(inside, 1.0, np.nan).reshape(gx.shape),
                      cmap=ListedColormap(["#e6e6e6"]), shading="auto", rasterized=True)
        return None
    return ax.pcolormesh(gx, gy, val.reshape(gx.shape), cmap="viridis", shading="auto",
                         rasterized=True, alpha=0.85)


def _speed_colorbar(fig: Figure, ax: Any, mesh: Any, label: str) -> None:
    """The map's colour bar; without one (F does not depend on the position) a note."""
    if mesh is not None:
        fig.colorbar(mesh, ax=ax, label=label)
    else:
        ax.text(0.99, 0.99, "F(x, u) does not depend on x here\n(grey: the domain)",
                transform=ax.transAxes, ha="right", va="top", fontsize=7)


def _arc_length(metric: Metric, points: np.ndarray) -> np.ndarray:
    """Cumulative length (sum of C) at every point of the path, ``(n+1,)``."""
    costs = np.asarray(metric.path_costs(points[None]), dtype=float)[0]
    return np.concatenate([[0.0], np.cumsum(costs)])


def _coordinates_against_length(ax: Any, metric: Metric, points: np.ndarray,
                                s: np.ndarray, ylabel: str) -> None:
    colors = matplotlib.colormaps["tab10"](np.arange(metric.dim) % 10)
    for j, name in enumerate(_coordinate_names(metric)):
        ax.plot(s, points[:, j], color=colors[j], lw=1.4, marker=".", ms=3, label=name)
    ax.set_xlabel("arc length (sum of C from the start)")
    ax.set_ylabel(ylabel)
    ax.legend(fontsize=7, ncol=min(metric.dim, 4))
    ax.grid(alpha=0.3)


def geodesic_path(metric: Metric, points: Any, title: str | None = None) -> Figure:
    """One path ``points`` ``(n+1, dim)`` of ``metric``.

    2-D: the path over a map of the metric (the mean of ``F(x, u)`` over unit directions
    ``u``; the height contours of the ``height_map`` hook and the boundary of where
    ``F(x, .)`` is convex, if the metric has them). 3-D: the (x0, x1) projection over the
    same map (headings as arrows for a planar pose, `is_planar_pose`) beside every
    coordinate against arc length. Higher dimensions: the coordinates (joint angles)
    against arc length, and, for a metric with kinematics (`has_kinematics`), the end
    effector's path seen from above and from the side with the metric's ``landmarks``."""
    p = np.asarray(points, dtype=float)
    if p.ndim != 2 or p.shape[1] != metric.dim or len(p) < 2:
        raise ValueError(f"points must have shape (n+1, {metric.dim}) with n >= 1, "
                         f"got {p.shape}")
    s = _arc_length(metric, p)
    head = title or f"{metric.name}: a path of {len(p) - 1} segments, length {s[-1]:.6g}"
    if metric.dim == 2:
        fig = new_figure((6.4, 5.6))
        ax = fig.subplots()
        mesh = _unit_speed_map(ax, metric)
        _speed_colorbar(fig, ax, mesh, "mean of F(x, u) over unit directions u")
        height = height_map(metric)
        lo, hi = metric.domain.bounds()
        if height is not None or not metric.convex_everywhere:
            gx, gy = np.meshgrid(np.linspace(lo[0], hi[0], 120), np.linspace(lo[1], hi[1], 120))
            pts = np.stack([gx.ravel(), gy.ravel()], 1)
            inside = metric.domain.contains(pts)
            if height is not None:
                h = np.full(len(pts), np.nan)
                h[inside] = np.asarray(height(pts[inside]), dtype=float)
                cs = ax.contour(gx, gy, h.reshape(gx.shape), levels=8, colors="white",
                                linewidths=0.6, alpha=0.8)
                ax.clabel(cs, fontsize=6, fmt="%.2f")
            if not metric.convex_everywhere:
                lam = np.full(len(pts), np.nan)
                lam[inside] = metric.convexity(pts[inside], n_directions=32)
                ax.contour(gx, gy, lam.reshape(gx.shape), levels=[0.0], colors="tab:red",
                           linewidths=1.0, linestyles="--")
        ax.plot(p[:, 0], p[:, 1], color="white", lw=3.2)
        ax.plot(p[:, 0], p[:, 1], color=EXACT_COLOR, lw=1.5, marker=".", ms=4, label="path")
        ax.plot(*p[0], "o", color="green", ms=7, label="start")
        ax.plot(*p[-1], "*", color="red", ms=11, label="goal")
        handles = ax.get_legend_handles_labels()[0]
        if height is not None:
            handles.append(Line2D([], [], color="grey", lw=0.6, label="height h(p) contours"))
        if not metric.convex_everywhere:
            handles.append(Line2D([], [], color="tab:red", ls="--", lw=1.0,
                                  label="boundary of F(x, .) convex"))
        ax.legend(handles=handles, fontsize=7, loc="lower left")
        names = _coordinate_names(metric)
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_aspect("equal")
        ax.set_title(head, fontsize=9)
        fig.tight_layout()
        return fig
    if metric.dim == 3:
        fig = new_figure((12, 5))
        ax, ax2 = fig.subplots(1, 2)
        mesh = _unit_speed_map(ax, metric, res=100)
        names = _coordinate_names(metric)
        _speed_colorbar(fig, ax, mesh, f"mean F(x, u), unit u in ({names[0]}, {names[1]}), "
                        f"{names[2]} at its centre")
        ax.plot(p[:, 0], p[:, 1], color="white", lw=3.2)
        ax.plot(p[:, 0], p[:, 1], color=EXACT_COLOR, lw=1.5, marker=".", ms=4, label="path")
        if is_planar_pose(metric):
            q = p[:: max(1, len(p) // 16)]
            ax.quiver(q[:, 0], q[:, 1], np.cos(q[:, 2]), np.sin(q[:, 2]), color="tab:blue",
                      angles="xy", scale=22, width=0.005, label=f"heading {names[2]}")
        ax.plot(*p[0, :2], "o", color="green", ms=7, label="start")
        ax.plot(*p[-1, :2], "*", color="red", ms=11, label="goal")
        ax.legend(fontsize=7, loc="lower left")
        ax.set_xlabel(names[0])
        ax.set_ylabel(names[1])
        ax.set_aspect("equal")
        ax.set_title(f"projection on ({names[0]}, {names[1]})", fontsize=9)
        _coordinates_against_length(ax2, metric, p, s, "coordinate value")
        ax2.set_title("every coordinate along the path", fontsize=9)
        fig.suptitle(head, fontsize=10)
        fig.tight_layout()
        return fig
    arm = has_kinematics(metric)
    fig = new_figure((15, 4.8) if arm else (7.5, 4.8))
    axes = fig.subplots(1, 3 if arm else 1, squeeze=False)[0]
    _coordinates_against_length(axes[0], metric, p, s,
                                "joint angle (rad)" if arm else "coordinate value")
    axes[0].set_title("joint angles along the path" if arm else "coordinates along the path",
                      fontsize=9)
    if arm:
        hand = np.asarray(metric.frame_positions(p), dtype=float)[:, -1, :]  # (n+1, 3)
        marks = metric.landmarks()
        for ax, (i, j), view in ((axes[1], (0, 1), "from above"),
                                 (axes[2], (0, 2), "from the side")):
            ax.plot(hand[:, i], hand[:, j], color=EXACT_COLOR, lw=1.5, marker=".", ms=3,
                    label="end effector")
            ax.plot(hand[0, i], hand[0, j], "o", color="green", ms=7, label="start")
            ax.plot(hand[-1, i], hand[-1, j], "*", color="red", ms=11, label="goal")
            for label, where in marks.items():
                w = np.asarray(where, dtype=float)
                if j < len(w):
                    ax.plot(w[i], w[j], "s", color="tab:red", ms=7, label=label)
                else:  # a point (x, y) of the floor plan: a vertical line seen from the side
                    ax.axvline(w[i], color="tab:red", ls="--", lw=1.0,
                               label=f"{label} (vertical)")
            ax.set_xlabel("xyz"[i] + " (world frame)")
            ax.set_ylabel("xyz"[j] + " (world frame)")
            ax.set_aspect("equal", adjustable="datalim")
            ax.set_title(f"end effector's path, {view}", fontsize=9)
            ax.legend(fontsize=7)
            ax.grid(alpha=0.3)
    fig.suptitle(head, fontsize=10)
    fig.tight_layout()
    return fig
