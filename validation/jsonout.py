"""JSON-ready copies of results: numpy values as Python ones, NaN and infinite numbers
(which standard JSON cannot hold) as ``None``. Shared by the reports and the commands."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

__all__ = ["jsonable"]


def jsonable(o: Any, nonfinite_as_text: bool = False) -> Any:
    """JSON-ready copy: numpy scalars/arrays to Python, non-finite floats to ``None`` (or,
    with ``nonfinite_as_text``, to ``"inf"``, ``"-inf"``, ``"nan"``: a counterexample keeps
    its value)."""
    if isinstance(o, dict):
        return {str(k): jsonable(v, nonfinite_as_text) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [jsonable(v, nonfinite_as_text) for v in o]
    if isinstance(o, np.ndarray):
        return jsonable(o.tolist(), nonfinite_as_text)
    if isinstance(o, (np.bool_, bool)):
        return bool(o)
    if isinstance(o, (np.integer, int)):
        return int(o)
    if isinstance(o, (np.floating, float)):
        f = float(o)
        if math.isfinite(f):
            return f
        return str(f) if nonfinite_as_text else None
    return o
