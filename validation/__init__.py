"""validation: learned-vs-exact benchmark reports and numerical checks of the paper's
propositions.

Python API::

    compare(policy, metric, pairs) -> Comparison          # success, length ratios, timing
    midpoint_error(policy, metric, pairs) -> MidpointErrors
    build_report(env, out, run=None, pairs=None, quick=False) -> dict   # report.md/json/PNGs
    plot_geodesic(metric, result, "path.png") -> Figure  # one solved path, drawn
    export_paths(result_or_results, "path.csv")          # .csv, .npy or .json

``validation.propositions`` holds the grid dynamic programming of eqs. (9)-(13) and the
Proposition 1 checks; ``validation.strategies`` the hypothesis strategies shared by the
property tests; ``validation.testing`` the property suite users point at their own metric
and policy (pytest classes to subclass, functions, ``geodesics check``). (``solvers`` and
``learn`` are imported lazily, on first use of the comparison API.)
"""

from __future__ import annotations

from typing import Any

__all__ = [
    "Comparison",
    "ExactPolicy",
    "ExactSet",
    "MidpointErrors",
    "PathSet",
    "StraightLine",
    "build_report",
    "compare",
    "exact_reference",
    "export_paths",
    "midpoint_error",
    "plot_geodesic",
    "ratio_stats",
]

_COMPARE = {"Comparison", "ExactPolicy", "ExactSet", "MidpointErrors", "PathSet",
            "StraightLine", "compare", "exact_reference", "midpoint_error", "ratio_stats"}


def __getattr__(name: str) -> Any:
    if name in _COMPARE:
        from validation import comparison as _c

        return getattr(_c, name)
    if name in ("export_paths", "plot_geodesic"):
        from validation import export as _e

        return getattr(_e, name)
    if name == "build_report":
        from validation.report import build_report

        return build_report
    raise AttributeError(f"module 'validation' has no attribute {name!r}")
