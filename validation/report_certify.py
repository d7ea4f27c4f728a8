"""The certificates of a report: ``lower <= d(s, g) <= upper`` for the
first pairs of a comparison, by `solvers.certify` in any dimension it accepts.

Every row is built from what the certificate carries, never from the metric's name: the
2-D mesh certificate (``CertifyResult``: triangles), the verified potential of 3-D and up
(``NDResult``: cells) and the conformal lower bound of dimension > 3
(``SplitCertifyResult``: boxes, ``bound_by``, ``trivial``) all have ``lower``, ``upper``,
``gap``, ``status`` (the toolkit's family), ``stopped_by``, ``rigour`` (what each part rests
on) and ``lp_status``; the row names their work counts as they are (``work``), their
``method`` (the result's own where it has one) and the source of each bound.

Budgets: in 2-D a report certifies ``QUICK_PAIRS`` pairs with the ``"coarse"`` preset
under ``--quick`` and ``FULL_PAIRS`` with ``"default"``; beyond 2-D ``QUICK_PAIRS_ND`` /
``FULL_PAIRS_ND`` pairs with ``"coarse"`` (the default presets of 3-D and up cost minutes a
pair). ``--certify N`` sets the count. Presets are work budgets (rounds, cells, boxes),
never time limits, so the same report gives the same intervals on any machine. The CPU
seconds and gaps per metric are in ``docs/guides/reports.md`` ("Certified distances in a
report"), measured by ``benchmarks/report_certify.py`` (its files in
``benchmarks/results/reports/``).
"""

from __future__ import annotations

import math
import time
from typing import Any

import solvers
from finsler import Metric
from finsler.errors import InputError
from validation.comparison import Comparison

#: Pairs certified by default by a quick report and by a full one, in 2-D and beyond.
QUICK_PAIRS, FULL_PAIRS = 2, 5
QUICK_PAIRS_ND, FULL_PAIRS_ND = 1, 2

#: Work counts a certificate may carry, in the order shown.
WORK_FIELDS = ("triangles", "cells", "relevant_cells", "boxes", "enclosures")

_METHOD_BY_WORK = {
    "triangles": "dual potential on a triangle mesh (LP), verified per triangle",
    "cells": "piecewise-linear potential on a cell mesh (LP), verified per cell",
}


def preset_for(metric: Metric, quick: bool) -> str:
    """The preset a report certifies with: ``"coarse"`` for a quick report and beyond 2-D
    (where the default presets cost minutes a pair), else ``"default"``."""
    return "coarse" if quick or metric.dim != 2 else "default"


def default_count(metric: Metric, quick: bool) -> int:
    """Pairs a report certifies when ``--certify`` is not given (see the module
    docstring for what they cost)."""
    if metric.dim == 2:
        return QUICK_PAIRS if quick else FULL_PAIRS
    return QUICK_PAIRS_ND if quick else FULL_PAIRS_ND


def certificate_row(c: Any) -> dict[str, Any]:
    """The fields of a report row common to every certificate ``c`` (any result of
    `solvers.certify`), chosen by what ``c`` carries."""
    work = {k: int(getattr(c, k)) for k in WORK_FIELDS if isinstance(
        getattr(c, k, None), (int, float))}
    method = getattr(c, "method", None) or next(
        (text for k, text in _METHOD_BY_WORK.items() if k in work), type(c).__name__)
    upper = float(c.upper)
    lower = float(c.lower)
    row: dict[str, Any] = {
        "lower": lower, "upper": upper, "gap": float(c.gap),
        "ratio": lower / upper if upper > 0 and math.isfinite(upper) else None,
        "status": c.status.label, "stopped_by": c.stopped_by.label,
        "work": work, "method": method,
        "bound_by": getattr(c, "bound_by", None) or "potential",
        "upper_source": getattr(c, "upper_source", None) or "path",
        "exact_length_proven_upper": float(getattr(c, "path_upper", upper)),
        "rigour": dict(getattr(c, "rigour", None) or {}),
    }
    if getattr(c, "trivial", None) is not None:  # the trivial bound beside the real one
        row["trivial_lower"] = float(c.trivial)
    if getattr(c, "convexity", None) is not None:
        row["convexity"] = c.convexity
    return row


def certified_intervals(cmp: Comparison, metric: Metric, count: int, quick: bool
                        ) -> dict[str, Any] | None:
    """Certified intervals ``lower <= d <= upper`` (`solvers.certify`) for the first
    ``count`` pairs of a comparison, with the exact path as the curve of the upper bound (no
    second solve), and per pair a PROVEN bound on how much longer than the distance the
    learned path (and the route search's) is: its proven length
    (`Metric.path_length_bounds`) over the certified lower bound. The preset is
    `preset_for`'s; its work budgets (rounds, triangles, cells, boxes) decide the
    refinement, never a wall-clock limit, so the same report gives the same intervals on
    any machine under any load. Each row (`certificate_row`, plus ``pair``,
    ``seconds`` (wall) and ``cpu_seconds``) has the certificate's ``status``
    (`solvers.CertifyStatus`; a failed refinement keeps the best interval proven,
    lower bound 0 if none, and an infinite excess bound); a pair that cannot be certified
    (bad input, e.g. start and goal too close, or a metric the certifiers do not accept)
    is listed with its ``error``. None where ``count`` is 0."""
    if count <= 0:
        return None
    mesh = preset_for(metric, quick)
    rows: list[dict[str, Any]] = []
    for i in range(min(count, len(cmp.pairs))):
        t0, c0 = time.perf_counter(), time.process_time()
        try:
            c = solvers.certify(metric, cmp.pairs[i, 0], cmp.pairs[i, 1], mesh,
                                path=cmp.exact.paths[i])
        except InputError as err:  # e.g. start and goal too close to certify
            rows.append({"pair": i, "error": str(err), "seconds": time.perf_counter() - t0,
                         "cpu_seconds": time.process_time() - c0})
            continue
        row = {"pair": i, **certificate_row(c), "seconds": time.perf_counter() - t0,
               "cpu_seconds": time.process_time() - c0}
        for w in ("learned", "searched"):
            ps = getattr(cmp, w, None)
            if ps is not None:
                up = metric.path_length_bounds(ps.paths[i]).upper
                row[f"{w}_length_proven_upper"] = up
                row[f"{w}_excess_bound"] = up / c.lower - 1.0 if c.lower > 0 else math.inf
        rows.append(row)
    return {"mesh": mesh, "pairs": rows}


def _excess(bound: float | None) -> str:
    """A proven excess bound as a percentage (``-`` where none is finite: no lower bound)."""
    return f"{100 * bound:.2f}%" if bound is not None and math.isfinite(bound) else "-"


def _work(r: dict[str, Any]) -> str:
    return ", ".join(f"{v} {k.replace('_', ' ')}" for k, v in r.get("work", {}).items())


def md_certified(doc: dict[str, Any]) -> list[str]:
    """The markdown section of the certified intervals (if computed)."""
    cert = doc.get("certified")
    if not cert:
        return []
    done = [r for r in cert["pairs"] if "error" not in r]
    has_s = any("searched_excess_bound" in r for r in done)
    lines = [
        "## Certified distances",
        "",
        f"For the first {len(cert['pairs'])} pair{'s' * (len(cert['pairs']) != 1)}, "
        f"`solvers.certify` ({cert['mesh']} "
        "preset) proves lower <= d(s, g) <= upper (a verified potential for the lower bound, "
        "the exact path's proven length for the upper). `bound by` says which potential "
        "gave the lower bound. The excess columns are PROVEN bounds on how much longer than "
        "the true distance the learned paths are: their proven length over the certified "
        "lower bound, minus 1. Work budgets (refinement rounds, triangles, cells, boxes) "
        "end the refinement, never a time limit (`stopped by`), so the intervals do not "
        "depend on the machine.",
        "",
        "| pair | lower | upper | gap | lower/upper | status | bound by | learned: excess <= |"
        + (" learned + route search: excess <= |" if has_s else "")
        + " stopped by | work | CPU s |",
        "|---|---|---|---|---|---|---|---|" + ("---|" if has_s else "") + "---|---|---|",
    ]
    for r in cert["pairs"]:
        if "error" in r:
            lines.append(f"| {r['pair']} | no certificate: {r['error']} |")
            continue
        ratio = f"{r['ratio']:.3f}" if r.get("ratio") is not None else "-"
        lines.append(f"| {r['pair']} | {r['lower']:.6g} | {r['upper']:.6g} | "
                     f"{r['gap']:.2e} | {ratio} | {r['status']} | {r['bound_by']} | "
                     f"{_excess(r.get('learned_excess_bound'))} |"
                     + (f" {_excess(r.get('searched_excess_bound'))} |" if has_s else "")
                     + f" {r['stopped_by']} | {_work(r)} | {r['cpu_seconds']:.1f} |")
    if done:
        first = done[0]
        lines += ["", f"Method (pair {first['pair']}): {first['method']}."]
        if "trivial_lower" in first:
            lines += ["", "Here the lower bound is a sound bound, not one refined to a target "
                      "interval; it must beat the trivial bound (the factor's proven minimum "
                      "times the Euclidean distance): "
                      + ", ".join(f"{r['trivial_lower']:.6g} (pair {r['pair']})"
                                  for r in done if "trivial_lower" in r) + "."]
        if "convexity" in first:
            lines += ["", f"Convexity: {first['convexity']} (where F(x, .) is not convex "
                      "the bound holds for the distance, that of the convexified metric)."]
        lines += ["", "Rigour: " + "; ".join(f"{k}: {v}" for k, v in first["rigour"].items())
                  + ".", ""]
    return lines


def cli_lines(doc: dict[str, Any]) -> list[str]:
    """The lines ``geodesics report`` prints for the certified intervals."""
    lines = []
    for r in (doc.get("certified") or {}).get("pairs", []):
        if "error" in r:
            lines.append(f"certified pair {r['pair']}: no certificate ({r['error']})")
            continue
        text = (f"certified pair {r['pair']}: {r['lower']:.6g} <= d <= {r['upper']:.6g} "
                f"(gap {r['gap']:.1e}, {r['status']}, "
                + (f"lower bound by {r['bound_by']}, " if r["bound_by"] != "potential" else "")
                + f"{_work(r)}, {r['cpu_seconds']:.1f} s CPU)")
        if "learned_excess_bound" in r:
            text += f"; learned path at most {_excess(r['learned_excess_bound'])} longer than d"
        if "searched_excess_bound" in r:
            text += f", with route search {_excess(r['searched_excess_bound'])}"
        lines.append(text)
    return lines
