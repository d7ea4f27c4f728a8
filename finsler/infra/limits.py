"""One place that bounds memory before allocating: every array whose size a user chooses
(quadrature order, tree depth, number of pairs) is checked here first, so that an
impossible request is a clear error with the figure, not a machine out of memory. The
numeric options of the public API (counts, tolerances, seeds) are checked for type and
range here too (`check_count`, `check_number`, `check_seed`)."""

from __future__ import annotations

import math
import numbers
from collections.abc import Sequence
from typing import Any

from finsler.errors import InputError, short

__all__ = ["MAX_BYTES", "check_count", "check_memory", "check_number", "check_seed",
           "rows_that_fit"]

#: Largest working set (bytes) a single request may need: 4 GiB.
MAX_BYTES = 4 * 1024**3


def check_memory(shape: Sequence[int], what: str, hint: str = "", itemsize: int = 8,
                 copies: int = 1) -> int:
    """Raise `InputError` if ``copies`` arrays of ``shape`` and ``itemsize`` bytes
    per element would exceed `MAX_BYTES`; returns the bytes needed otherwise."""
    need = math.prod(int(s) for s in shape) * itemsize * copies
    if need > MAX_BYTES:
        raise InputError(f"{what} would need about {need / 1024**3:.3g} GiB (arrays of shape "
                         f"{tuple(int(s) for s in shape)}), over the limit of "
                         f"{MAX_BYTES / 1024**3:g} GiB" + (f"; {hint}" if hint else ""))
    return need


def rows_that_fit(row_shape: Sequence[int], what: str, hint: str = "", itemsize: int = 8,
                  copies: int = 1) -> int:
    """How many independent rows of ``row_shape`` (``copies`` arrays of ``itemsize`` bytes
    per element) fit `MAX_BYTES` at once, at least 1: the part size of work that is
    split into rows. Raises `InputError` (`check_memory`) if one row does not
    fit."""
    need = check_memory((1, *row_shape), what, hint, itemsize, copies)
    return max(1, MAX_BYTES // max(need, 1))


def _got(value: Any) -> str:
    return f"{type(value).__name__} {short(repr(value), 80)}"


def check_count(value: Any, name: str, low: int = 1, high: int | None = None) -> int:
    """``value`` as an ``int`` if it is an integer (Python or numpy, not a bool) with
    ``low <= value <= high``; else `InputError` naming ``name`` and the value.
    ``high`` is the caller's memory or time limit (None: no limit)."""
    kind = {0: "a non-negative integer", 1: "a positive integer"}.get(low,
                                                                    f"an integer >= {low}")
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise InputError(f"{name} must be {kind}, got {_got(value)}")
    if value < low:
        raise InputError(f"{name} must be {kind}, got {int(value)}")
    if high is not None and value > high:
        raise InputError(f"{name} = {short(str(int(value)), 40)} is above the limit of "
                         f"{high}")
    return int(value)


def check_number(value: Any, name: str, low: float = -math.inf, high: float = math.inf, *,
                 low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a ``float`` if it is a real number (not a bool, not complex), finite,
    in the interval from ``low`` to ``high`` (``low_open`` / ``high_open``: the end itself
    excluded); else `InputError` naming ``name`` and the value."""
    lo = "(" if low_open else "["
    hi = ")" if high_open else "]"
    span = f"in {lo}{low:g}, {high:g}{hi}"
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InputError(f"{name} must be a finite number {span}, got {_got(value)}")
    x = float(value)
    if not math.isfinite(x) or x < low or x > high or (low_open and x == low) or (
            high_open and x == high):
        raise InputError(f"{name} must be a finite number {span}, got {value!r}")
    return x


def check_seed(seed: Any, name: str = "seed") -> Any:
    """A seed numpy's ``default_rng`` takes: an integer >= 0, a ``numpy.random.Generator``
    (returned as it is), a non-empty sequence of integers >= 0, or None (fresh entropy:
    not reproducible); else `InputError` naming ``name``."""
    import numpy as np

    if seed is None or isinstance(seed, np.random.Generator):
        return seed
    if isinstance(seed, (list, tuple)) and seed and all(
            isinstance(s, numbers.Integral) and not isinstance(s, bool) and s >= 0
            for s in seed):
        return seed
    if isinstance(seed, bool) or not isinstance(seed, numbers.Integral) or seed < 0:
        raise InputError(f"{name} must be an integer >= 0 or a numpy Generator, got "
                         f"{_got(seed)}")
    return int(seed)
